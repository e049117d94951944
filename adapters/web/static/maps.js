/* The operator page's mappings panel: every map of the bus's map nodes with its live input
   and output, its curve drawn (SVG), breakpoints dragged to edit, ranges and smoothing as
   fields, enable, learn, undo, and save per node. Each change is a `map` request to the
   node that runs the map (adapters/web/maps.py); a refused one shows its reason in place,
   under the map, and the map is drawn again as it runs. Protocol: docs/web.md. */
"use strict";

(() => {
  const {el, fixed, link} = sonibus;
  const SVG = "http://www.w3.org/2000/svg";
  const W = 200, H = 120, PAD = 8;     // the curve's box, in SVG units
  const CURVES = ["linear", "exp", "log", "s", "points"];
  const views = new Map();             // "node/map" → MapView

  function svg(tag, attributes) {
    const node = document.createElementNS(SVG, tag);
    for (const [name, value] of Object.entries(attributes || {})) node.setAttribute(name, value);
    return node;
  }
  const px = (x) => PAD + x * (W - 2 * PAD);
  const py = (y) => H - PAD - y * (H - 2 * PAD);

  /** Send `verb` with `args` to map node `node`; `done(reply)` gets its reply. */
  function ask(node, verb, args, what, done) {
    return link.send({type: "map", node, verb, args}, what, (reply) => { if (done) done(reply); return false; });
  }

  class MapView {
    constructor(node, map) {
      this.node = node;
      this.name = map.name;
      this.dragging = null;            // the index of the point being dragged
      this.points = null;              // the breakpoints as the page holds them while dragged
      this.error = el("output", {class: "map-error", role: "alert"});
      this.inValue = el("span", {class: "map-in"});
      this.outValue = el("span", {class: "map-out"});
      this.curve = svg("svg", {class: "map-curve", viewBox: `0 0 ${W} ${H}`, width: W, height: H});
      this.enabled = el("input", {type: "checkbox", class: "map-enabled", title: "run this map",
        onchange: () => this.edit({enabled: this.enabled.checked}, this.enabled.checked ? "enable" : "disable")});
      this.kind = el("select", {class: "map-curve-kind", title: "curve",
        onchange: () => this.changeCurve(this.kind.value)}, ...CURVES.map((c) => el("option", {value: c}, c)));
      const field = (cls, title, onchange) => el("input", {type: "number", step: "any", class: cls, title, onchange});
      this.toLow = field("map-to-low", "to: the output at the curve's bottom", () => this.editTo());
      this.toHigh = field("map-to-high", "to: the output at the curve's top", () => this.editTo());
      this.fromLow = field("map-from-low", "from: the source's value at x = 0 (empty: its info's range)",
        () => this.editFrom());
      this.fromHigh = field("map-from-high", "from: the source's value at x = 1 (empty: its info's range)",
        () => this.editFrom());
      this.fromRow = el("label", {}, "from ", this.fromLow, " … ", this.fromHigh);
      this.smooth = field("map-smooth", "smoothing time constant, ms (0: none)", () => {
        const ms = Number(this.smooth.value);
        this.edit(ms > 0 ? {smooth_ms: ms} : {}, "smoothing", ms > 0 ? [] : ["smooth_ms"]);
      });
      this.learning = el("span", {class: "map-learning"});
      this.section = el("article", {class: "map", dataset: {node, map: map.name}},
        el("header", {},
          el("label", {}, this.enabled, el("b", {}, map.name)), " ",
          el("span", {class: "map-source"}), " ", this.learning,
          el("span", {class: "map-buttons"},
            el("button", {type: "button", class: "map-learn", title: "the next 5 s of the source set its range",
              onclick: () => ask(node, "learn", {map: map.name, seconds: 5}, `learn ${map.name}`,
                (reply) => this.answered(reply))}, "learn"),
            el("button", {type: "button", class: "map-undo", title: "take back the last change",
              onclick: () => ask(node, "undo", {map: map.name}, `undo ${map.name}`,
                (reply) => this.answered(reply))}, "undo"),
            el("button", {type: "button", class: "map-remove",
              title: "take this map out (its output stops; the node's undo brings it back)",
              onclick: () => ask(node, "remove", {map: map.name}, `remove ${map.name}`,
                (reply) => this.answered(reply))}, "remove"))),
        el("div", {class: "map-body"}, this.curve,
          el("div", {class: "map-fields"},
            el("div", {class: "map-live"}, "in ", this.inValue, " → out ", this.outValue),
            el("label", {}, "curve ", this.kind),
            this.fromRow,
            el("label", {}, "to ", this.toLow, " … ", this.toHigh),
            el("label", {}, "smooth ", this.smooth, " ms"))),
        this.error);
      this.curve.addEventListener("pointermove", (event) => this.drag(event));
      this.curve.addEventListener("pointerup", (event) => this.drop(event));
      this.curve.addEventListener("pointercancel", (event) => this.drop(event));
      this.update(map);
    }

    /** The map as its node runs it now (not while a point is dragged: the drag wins until dropped). */
    update(map) {
      this.map = map;
      if (this.dragging !== null) return;
      const table = map.table || {};
      this.section.classList.toggle("disabled", !map.enabled);
      this.enabled.checked = !!map.enabled;
      this.section.querySelector(".map-source").textContent =
        table.source || Object.entries(table.sources || {}).map(([k, v]) => `${k}=${v}`).join(", ");
      const kind = table.curve || (table.points ? "points" : "linear");
      this.kind.value = kind;
      const active = document.activeElement;
      const from = Array.isArray(table.from) ? table.from : ["", ""];  // (one source; several: in the file)
      this.fromRow.hidden = (map.sources || []).length !== 1;
      for (const [input, value] of [[this.toLow, map.to[0]], [this.toHigh, map.to[1]],
                                    [this.fromLow, from[0]], [this.fromHigh, from[1]],
                                    [this.smooth, table.smooth_ms || 0]]) {
        if (input !== active) input.value = String(value);
      }
      this.points = kind === "points" ? table.points.map((p) => [p[0], p[1]]) : null;
      this.draw();
    }

    /** Live values: the curve's input (0..1) and the output, and a learn under way. */
    live(values) {
      this.values = values || {};
      const {input, output, silent, learning} = this.values;
      this.inValue.textContent = fixed(input, 3);
      this.outValue.textContent = Number.isFinite(output) ? `${Number(output.toPrecision(6))} ${this.map.unit || ""}` : "–";
      this.section.classList.toggle("silent", !!silent);
      this.learning.textContent = learning ? `learning ${learning.source}…` : (silent ? "silent" : "");
      const dot = this.curve.querySelector(".live");
      if (dot && Number.isFinite(input)) {
        dot.setAttribute("cx", px(input));
        dot.setAttribute("cy", py(this.at(input)));
        dot.style.display = "";
      }
    }

    /** The curve's value at `x`: between the held breakpoints, else from the node's samples. */
    at(x) {
      const line = this.points || this.map.curve;
      if (x <= line[0][0]) return line[0][1];
      for (let i = 1; i < line.length; i += 1) {
        const [x0, y0] = line[i - 1], [x1, y1] = line[i];
        if (x <= x1) return x1 === x0 ? y1 : y0 + (y1 - y0) * (x - x0) / (x1 - x0);
      }
      return line[line.length - 1][1];
    }

    draw() {
      const line = this.points || this.map.curve;
      const frame = svg("rect", {class: "frame", x: PAD, y: PAD, width: W - 2 * PAD, height: H - 2 * PAD});
      const path = svg("polyline", {class: "curve", points: line.map(([x, y]) => `${px(x)},${py(y)}`).join(" ")});
      const dot = svg("circle", {class: "live", r: 4, cx: -10, cy: -10});
      dot.style.display = "none";
      const handles = (this.points || []).map(([x, y], i) => {
        const handle = svg("circle", {class: "point", r: 6, cx: px(x), cy: py(y), "data-index": i});
        handle.addEventListener("pointerdown", (event) => {
          event.preventDefault();
          this.curve.setPointerCapture(event.pointerId);
          this.dragging = i;
          this.error.textContent = "";
        });
        return handle;
      });
      this.curve.replaceChildren(frame, path, ...handles, dot);
      if (this.values) this.live(this.values);
    }

    /** A point moved to where the pointer is: x between its neighbours, y within 0..1. */
    drag(event) {
      if (this.dragging === null) return;
      const box = this.curve.getBoundingClientRect();
      const x = ((event.clientX - box.left) * W / box.width - PAD) / (W - 2 * PAD);
      const y = (H - PAD - (event.clientY - box.top) * H / box.height) / (H - 2 * PAD);
      const i = this.dragging, points = this.points;
      const low = i === 0 ? 0 : points[i - 1][0] + 0.001;
      const high = i === points.length - 1 ? 1 : points[i + 1][0] - 0.001;
      points[i] = [round(Math.min(high, Math.max(low, x))), round(Math.min(1, Math.max(0, y)))];
      this.draw();
    }

    drop() {
      if (this.dragging === null) return;
      this.dragging = null;
      this.edit({points: this.points}, "curve");
    }

    changeCurve(kind) {
      if (kind === "points") {  // the curve as it is, as five breakpoints to drag
        const points = [0, 0.25, 0.5, 0.75, 1].map((x) => [x, round(this.at(x))]);
        this.edit({curve: "points", points}, "curve");
      } else {
        this.edit({curve: kind}, "curve");
      }
    }

    editFrom() {
      const [low, high] = [this.fromLow.value.trim(), this.fromHigh.value.trim()];
      if (low === "" && high === "") this.edit({}, "source range", ["from"]);  // (back to its info's)
      else this.edit({from: [low === "" ? null : Number(low), high === "" ? null : Number(high)]}, "source range");
    }

    editTo() {
      this.edit({to: [Number(this.toLow.value), Number(this.toHigh.value)]}, "range");
    }

    /** Send an edit; a refusal shows under the map and the map is drawn as it runs. */
    edit(set, what, unset) {
      ask(this.node, "edit", {map: this.name, set, unset: unset || []}, `${this.name} ${what}`,
        (reply) => this.answered(reply));
    }

    answered(reply) {
      this.error.textContent = reply.ok ? "" : reply.error || "refused";
      this.section.classList.toggle("refused", !reply.ok);
      if (!reply.ok) this.update(this.map);  // (the last good version, as it runs)
      else if (reply.result && reply.result.table) this.update({...this.map, table: reply.result.table,
        to: reply.result.table.to || this.map.to});
    }
  }

  function round(v) { return Math.round(v * 1000) / 1000; }

  const blocks = new Map();            // node → its block (kept: a button replaced under a click would lose it)

  function nodeBlock(node) {
    let block = blocks.get(node);
    if (block) return block;
    const save = el("button", {type: "button", class: "map-save", title: "write the maps into the installation file",
      onclick: () => ask(node, "save", {}, `save ${node}'s maps`, (reply) => {
        saved.textContent = reply.ok ? `saved into ${reply.result.file}` : reply.error;
        saved.dataset.kind = reply.ok ? "ok" : "error";
      })}, "save");
    const saved = el("output", {class: "map-saved"});
    // after a stop, the robots whose maps it halted, and the button that asks the node to resume them
    // (<node>/program/resume, as `sonibus resume` does); the node's answer shown as it came
    const resumed = el("output", {class: "map-resumed"});
    const resume = el("button", {type: "button", class: "map-resume", title: "let these maps move their robots again",
      onclick: () => ask(node, "resume", {}, `resume ${node}'s maps`, (reply) => {
        const robots = reply.ok ? reply.result.resumed || [] : [];
        resumed.textContent = !reply.ok ? reply.error
          : robots.length ? `resumed: ${robots.join(", ")}` : "resumed: none was halted";
        resumed.dataset.kind = reply.ok ? "ok" : "error";
      })}, "resume");
    const halted = el("p", {class: "map-halted", hidden: true}, el("span", {class: "map-halted-robots"}), " ", resume);
    // a map added live: its name and source (the rest: edited in place once it runs); the node's
    // last change of any map taken back (a removal too)
    const name = el("input", {type: "text", class: "map-add-name", placeholder: "name", size: 10});
    const source = el("input", {type: "text", class: "map-add-source", placeholder: "source: pepper/joints/HeadYaw",
      size: 28});
    const added = el("output", {class: "map-add-error", role: "alert"});
    const shown = (reply) => { added.textContent = reply.ok ? "" : reply.error; };
    const add = el("button", {type: "button", class: "map-add", title: "run a new map of this source",
      onclick: () => ask(node, "add", {map: name.value.trim(), table: {source: source.value.trim()}},
        `add ${name.value.trim()}`, (reply) => { shown(reply); if (reply.ok) name.value = source.value = ""; })},
      "add");
    const undo = el("button", {type: "button", class: "map-node-undo", title: "take back the node's last change",
      onclick: () => ask(node, "undo", {}, `undo ${node}'s last change`, shown)}, "undo");
    block = el("div", {class: "map-node", dataset: {node}}, el("h3", {}, node, " ", save, " ", saved),
      halted, resumed, el("div", {class: "map-list"}),
      el("p", {class: "map-adding"}, name, " ", source, " ", add, " ", undo, " ", added));
    blocks.set(node, block);
    return block;
  }

  function onMaps(message) {
    const panel = document.getElementById("mappings");
    const container = document.getElementById("maps");
    const seen = new Set();
    const shown = [];
    for (const node of message.nodes || []) {
      const block = nodeBlock(node.node);
      const sections = [];
      for (const map of node.maps || []) {
        const id = `${node.node}/${map.name}`;
        seen.add(id);
        let view = views.get(id);
        if (view) view.update(map);
        else views.set(id, view = new MapView(node.node, map));
        sections.push(view.section);
      }
      const list = block.querySelector(".map-list");
      if (sections.some((section, i) => list.children[i] !== section) || list.children.length !== sections.length) {
        list.replaceChildren(...sections);  // (only when the maps changed: a section is kept under the pointer)
      }
      shown.push(block);
    }
    for (const id of [...views.keys()]) if (!seen.has(id)) views.delete(id);
    for (const node of [...blocks.keys()]) if (!shown.includes(blocks.get(node))) blocks.delete(node);
    if (shown.some((block, i) => container.children[i] !== block) || container.children.length !== shown.length) {
      container.replaceChildren(...shown);
    }
    panel.hidden = shown.length === 0;
  }

  function onValues(message) {
    for (const [node, robots] of Object.entries(message.halted || {})) {
      const line = blocks.get(node)?.querySelector(".map-halted");
      if (!line) continue;
      line.hidden = robots.length === 0;
      line.querySelector(".map-halted-robots").textContent = `${robots.join(", ")}: halted by stop —`;
    }
    for (const [node, maps] of Object.entries(message.nodes || {})) {
      for (const [name, values] of Object.entries(maps || {})) {
        const view = views.get(`${node}/${name}`);
        if (view) view.live(values);
      }
    }
  }

  link.on.maps = onMaps;
  link.on.map_values = onValues;
  sonibus.maps = views;  // for tests
})();
