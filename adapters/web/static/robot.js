/* One robot on the operator page: its joints live (values, range bars, strip charts
   per joint group, drawn when the page's animation frame asks) and its controls from
   its info (behaviors, postures, say, awareness, head and arm sliders throttled to
   slider_hz). Plain script: it adds `sonibus.RobotView`. */
"use strict";

(() => {
  const {el, status, fixed} = sonibus;
  const HISTORY = 600;          // frames kept per robot for the charts (24 s at 25/s)
  const CHART_S = 6;            // seconds a chart shows
  const TOUCHED_MS = 1500;      // a slider the operator moved is left alone this long before it follows the robot
  const COLOURS = ["#4fc3f7", "#ffb74d", "#81c784", "#e57373", "#ba68c8", "#fff176", "#4db6ac", "#f06292"];
  const GROUPS = [
    ["Head", (name) => name.startsWith("Head")],
    ["Left arm", (name) => /^L(Shoulder|Elbow|Wrist|Hand)/.test(name)],
    ["Right arm", (name) => /^R(Shoulder|Elbow|Wrist|Hand)/.test(name)],
    ["Body", () => true],
  ];
  const SLIDER_GROUPS = new Set(["Head", "Left arm", "Right arm"]);
  const STATES = {connected: "connected", connecting: "not connected: connecting", lost: "not connected: lost",
    not_answering: "not answering", standby: "standby: another owner keeps it"};  // (bus/connection.py)

  function groupOf(name) {
    return GROUPS.find(([, test]) => test(name))[0];
  }

  function shortName(behavior) {
    return behavior.split("/").pop();
  }

  /** One robot: its section of the page, its latest frame and its recent history.
      `page`: {command(robot, verb, args, done), note(what, ms), settings, redraw()}. */
  class RobotView {
    constructor(name, info, page) {
      this.name = name;
      this.info = info;
      this.page = page;
      this.joints = new Map(info.joints.map((joint) => [joint.name, joint]));
      this.values = new Map();         // joint → latest value
      this.times = new Float64Array(HISTORY);
      this.history = new Map(info.joints.map((joint) => [joint.name, new Float32Array(HISTORY)]));
      this.count = 0;                  // frames taken (the ring's write position is count % HISTORY)
      this.rate = {frames: 0, since: performance.now(), hz: 0};
      this.touched = new Map();        // slider joint → when the operator last moved it
      this.throttle = new Map();       // slider joint → {last (ms), value, timer}
      this.section = this.build();
    }

    build() {
      const joints = this.info.joints;
      this.cells = new Map();
      this.bars = new Map();
      this.sliders = new Map();
      this.behaviorButtons = new Map();
      this.charts = [];
      const groups = GROUPS.map(([group]) => [group, joints.filter((j) => groupOf(j.name) === group)])
        .filter(([, members]) => members.length);
      this.connection = el("span", {class: "robot-connection"});
      this.rateLabel = el("span", {class: "robot-rate"});
      const header = el("header", {},
        el("h2", {}, this.name),
        el("span", {class: "robot-meta"}, `${this.info.model || "robot"} · ${this.info.owner || "no owner"}`),
        this.connection, this.rateLabel);
      const charts = el("div", {class: "charts"}, ...groups.map(([group, members]) => this.chart(group, members)));
      const table = el("table", {class: "joints"},
        el("thead", {}, el("tr", {}, el("th", {}, "joint"), el("th", {}, "value"), el("th", {}, "range"))),
        el("tbody", {}, ...joints.map((joint) => this.jointRow(joint))));
      const controls = el("div", {class: "controls"},
        this.behaviorBox(), this.postureBox(), this.sayBox(), this.awarenessBox(),
        ...groups.filter(([group]) => SLIDER_GROUPS.has(group))
          .map(([group, members]) => this.sliderBox(group, members)));
      const section = el("section", {class: "robot", dataset: {robot: this.name}}, header, charts,
        el("div", {class: "robot-body"}, el("div", {class: "joint-list"}, table), controls));
      this.update(this.info);
      return section;
    }

    update(info) {
      this.info = info;
      const state = (info.connection || {}).state || (info.connected === false ? "lost" : "connected");
      const error = (info.connection || {}).error;
      this.connection.textContent = STATES[state] || state;
      this.connection.title = error || "";
      this.connection.dataset.state = state;
    }

    chart(group, members) {
      const canvas = el("canvas", {height: 90, dataset: {chart: group}});
      const legend = el("div", {class: "legend"}, ...members.map((joint, i) =>
        el("span", {style: `color:${COLOURS[i % COLOURS.length]}`}, joint.name)));
      const chart = {canvas, members, width: 0, height: 0};
      // Sizes come from a ResizeObserver: reading clientWidth while drawing would force a layout every frame.
      new ResizeObserver(([entry]) => {
        const ratio = window.devicePixelRatio || 1;
        chart.width = Math.max(Math.round(entry.contentRect.width * ratio), 10);
        chart.height = Math.max(Math.round(entry.contentRect.height * ratio), 10);
        this.fresh = true;
        this.page.redraw();
      }).observe(canvas);
      this.charts.push(chart);
      return el("figure", {class: "chart"}, el("figcaption", {}, group), canvas, legend);
    }

    jointRow(joint) {
      const cell = el("td", {class: "value", dataset: {joint: joint.name}}, "–");
      const bar = el("span", {class: "bar-fill"});
      this.cells.set(joint.name, cell);
      this.bars.set(joint.name, bar);
      return el("tr", {},
        el("th", {scope: "row"}, joint.name), cell,
        el("td", {class: "range", title: `${fixed(joint.min, 2)} … ${fixed(joint.max, 2)}`},
          el("span", {class: "range-bar"}, bar)));
    }

    behaviorBox() {
      const behaviors = this.info.behaviors || [];
      const buttons = behaviors.map((name) => {
        const badge = el("span", {class: "badge"});
        const button = el("button", {type: "button", class: "behavior", title: name,
          dataset: {behavior: name, state: "idle"}, onclick: () => this.runBehavior(name, button)},
        shortName(name), badge);
        this.behaviorButtons.set(name, button);
        return button;
      });
      return el("fieldset", {class: "behaviors"}, el("legend", {}, "Behaviors"),
        buttons.length ? el("div", {class: "buttons"}, ...buttons) : el("p", {class: "empty"}, "none"));
    }

    postureBox() {
      const postures = this.info.postures || [];
      return el("fieldset", {class: "postures"}, el("legend", {}, "Postures"),
        postures.length ? el("div", {class: "buttons"}, ...postures.map((name) =>
          el("button", {type: "button", dataset: {posture: name},
            onclick: () => this.command("posture", {name})}, name)))
          : el("p", {class: "empty"}, "none"));
    }

    sayBox() {
      const input = el("input", {type: "text", maxlength: 500, placeholder: "Text to say", dataset: {say: this.name},
        "aria-label": `text for ${this.name} to say`});
      const form = el("form", {class: "say", onsubmit: (event) => {
        event.preventDefault();
        const text = input.value.trim();
        if (!text) return status("say: the text is empty — type something first", "error");
        if (this.command("say", {text}) !== null) input.value = "";
      }}, input, el("button", {type: "submit"}, "Say"));
      return el("fieldset", {}, el("legend", {}, "Say"), form);
    }

    awarenessBox() {
      const box = el("input", {type: "checkbox", dataset: {awareness: this.name},
        onchange: () => this.command("awareness", {enabled: box.checked})});
      return el("fieldset", {class: "awareness"}, el("legend", {}, "Awareness"),
        el("label", {}, box, " basic awareness (look at people)"));
    }

    sliderBox(group, members) {
      return el("fieldset", {class: "sliders"}, el("legend", {}, group), ...members.map((joint) => {
        const output = el("output", {}, "–");
        const slider = el("input", {type: "range", min: joint.min, max: joint.max,
          step: Math.max((joint.max - joint.min) / 500, 0.001), value: (joint.min + joint.max) / 2,
          dataset: {slider: joint.name}, "aria-label": `${this.name} ${joint.name}`});
        slider.addEventListener("input", () => {
          this.touched.set(joint.name, performance.now());
          output.textContent = fixed(Number(slider.value), 2);
          this.moveJoint(joint.name, Number(slider.value));
        });
        this.sliders.set(joint.name, {slider, output});
        return el("label", {class: "slider"}, el("span", {}, joint.name), slider, output);
      }));
    }

    command(verb, args, done) {
      return this.page.command(this.name, verb, args, done);
    }

    runBehavior(name, button) {
      const before = button.dataset.state;
      button.dataset.clicked = String(performance.now());
      button.dataset.state = "starting";
      const sent = this.command("behavior/run", {name}, (reply, ms) => {
        this.page.note("behavior reply", ms);
        if (reply.ok || button.dataset.state !== "starting") return false;
        delete button.dataset.clicked;
        // Refused: "already running" leaves it running; anything else is a failure to start.
        this.behaviorState(name, before === "running" ? "started" : "failed", reply.error);
        return false;
      });
      if (sent === null) button.dataset.state = before;
    }

    behaviorState(name, state, error) {
      const button = this.behaviorButtons.get(name);
      if (!button) return;
      const shown = {started: "running", stopped: "done", failed: "failed"}[state] || state;
      if (shown === "running" && button.dataset.clicked) {
        this.page.note("behavior running", performance.now() - Number(button.dataset.clicked));
        delete button.dataset.clicked;
      }
      button.dataset.state = shown;
      button.querySelector(".badge").textContent = shown === "idle" ? "" : shown;
      button.title = error ? `${name}: ${error}` : name;
    }

    /** A slider's value, sent at most slider_hz times a second; the latest wins. */
    moveJoint(joint, value) {
      const entry = this.throttle.get(joint) || {last: -Infinity, value, timer: null};
      entry.value = value;
      this.throttle.set(joint, entry);
      const period = 1000 / Math.max(this.page.settings.slider_hz, 0.1);
      const send = () => {
        entry.timer = null;
        entry.last = performance.now();
        // Shown: refusals only (the joint moving says the rest; a move the node held when STOP came is cancelled).
        this.command("joints/set", {names: [joint], angles: [entry.value]},
          (reply) => reply.ok || (reply.error || "").startsWith("cancelled"));
      };
      const wait = entry.last + period - performance.now();
      if (wait <= 0 && entry.timer === null) send();
      else if (entry.timer === null) entry.timer = setTimeout(send, wait);
    }

    dropHeldMoves() {
      for (const entry of this.throttle.values()) {
        clearTimeout(entry.timer);
        entry.timer = null;
      }
    }

    take(frame) {
      const slot = this.count % HISTORY;
      this.times[slot] = frame.t;
      frame.names.forEach((name, i) => {
        this.values.set(name, frame.v[i]);
        const ring = this.history.get(name);
        if (ring) ring[slot] = frame.v[i];
      });
      this.count += 1;
      this.rate.frames += 1;
      this.fresh = true;
    }

    render(now) {
      if (now - this.rate.since >= 1000) {
        this.rate.hz = this.rate.frames * 1000 / (now - this.rate.since);
        this.rate = {frames: 0, since: now, hz: this.rate.hz};
        this.rateLabel.textContent = `${this.rate.hz.toFixed(0)} frames/s`;
      }
      if (!this.fresh) return false;
      this.fresh = false;
      for (const [name, value] of this.values) {
        const cell = this.cells.get(name);
        if (!cell) continue;
        cell.textContent = fixed(value, 3);
        const joint = this.joints.get(name);
        const span = joint.max - joint.min;
        const share = span > 0 ? Math.min(Math.max((value - joint.min) / span, 0), 1) : 0.5;
        this.bars.get(name).style.transform = `scaleX(${share.toFixed(3)})`;
        const control = this.sliders.get(name);
        if (control && document.activeElement !== control.slider
            && now - (this.touched.get(name) || -Infinity) > TOUCHED_MS) {
          control.slider.value = value;
          control.output.textContent = fixed(value, 2);
        }
      }
      for (const chart of this.charts) this.drawChart(chart);
      return true;
    }

    drawChart({canvas, members, width, height}) {
      if (!width) return;  // not laid out yet
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
      const n = Math.min(this.count, HISTORY);
      if (n < 2) return;
      const newest = this.times[(this.count - 1) % HISTORY];
      g.lineWidth = 1.5 * ratio;
      members.forEach((joint, m) => {
        const ring = this.history.get(joint.name);
        const span = joint.max - joint.min || 1;
        g.strokeStyle = COLOURS[m % COLOURS.length];
        g.beginPath();
        let started = false;
        for (let k = n; k >= 1; k--) {
          const slot = (this.count - k) % HISTORY;
          const age = newest - this.times[slot];
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

  sonibus.RobotView = RobotView;
})();
