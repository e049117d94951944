/* A strip chart of one joint group on the operator page: the last CHART_S seconds of
   each member joint, scaled to its limits, drawn when the page's animation frame asks.
   Plain script: it adds `sonibus.StripChart`. */
"use strict";

(() => {
  const {el} = sonibus;
  const CHART_S = 6;            // seconds a chart shows
  const COLOURS = ["#4fc3f7", "#ffb74d", "#81c784", "#e57373", "#ba68c8", "#fff176", "#4db6ac", "#f06292"];

  class StripChart {
    /** `members`: the group's joints ({name, min, max}); `resized()` is called when its size changed. */
    constructor(group, members, resized) {
      this.members = members;
      this.width = 0;
      this.height = 0;
      this.canvas = el("canvas", {height: 90, dataset: {chart: group}});
      const legend = el("div", {class: "legend"}, ...members.map((joint, i) =>
        el("span", {style: `color:${COLOURS[i % COLOURS.length]}`}, joint.name)));
      // Sizes come from a ResizeObserver: reading clientWidth while drawing would force a layout every frame.
      new ResizeObserver(([entry]) => {
        const ratio = window.devicePixelRatio || 1;
        this.width = Math.max(Math.round(entry.contentRect.width * ratio), 10);
        this.height = Math.max(Math.round(entry.contentRect.height * ratio), 10);
        resized();
      }).observe(this.canvas);
      this.figure = el("figure", {class: "chart"}, el("figcaption", {}, group), this.canvas, legend);
    }

    /** Draw from the rings: `times` (s) and `history` (joint → values), `count` frames written so far. */
    draw(times, history, count) {
      const {canvas, members, width, height} = this;
      if (!width) return;  // not laid out yet (or hidden)
      const ratio = window.devicePixelRatio || 1;
      if (canvas.width !== width || canvas.height !== height) {
        canvas.width = width;
        canvas.height = height;
      }
      const g = canvas.getContext("2d");
      g.clearRect(0, 0, width, height);
      g.strokeStyle = "rgba(255,255,255,0.08)";
      g.lineWidth = 1;
      for (const y of [0.25, 0.5, 0.75]) {
        g.beginPath();
        g.moveTo(0, y * height);
        g.lineTo(width, y * height);
        g.stroke();
      }
      const size = times.length;
      const n = Math.min(count, size);
      if (n < 2) return;
      const newest = times[(count - 1) % size];
      g.lineWidth = 1.5 * ratio;
      members.forEach((joint, m) => {
        const ring = history.get(joint.name);
        const span = joint.max - joint.min || 1;
        g.strokeStyle = COLOURS[m % COLOURS.length];
        g.beginPath();
        let started = false;
        for (let k = n; k >= 1; k--) {
          const slot = (count - k) % size;
          const age = newest - times[slot];
          if (age > CHART_S) continue;
          const x = width * (1 - age / CHART_S);
          const y = height * (1 - (ring[slot] - joint.min) / span);
          if (started) g.lineTo(x, y);
          else g.moveTo(x, y);
          started = true;
        }
        g.stroke();
      });
    }
  }

  sonibus.StripChart = StripChart;
})();
