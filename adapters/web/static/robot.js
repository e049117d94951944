/* One robot on the operator page: its summary line (state, what it runs and says), and
   its panel: the controls from its info (behaviors, postures, say, awareness, head and
   arm sliders wide enough for fine moves, throttled to slider_hz), its strip charts
   (chart.js) and its joints live. The controls follow the robot's state: disabled while
   it is not connected, awareness as its owner says it. Plain script: it adds
   `sonibus.RobotView`. */
"use strict";

(() => {
  const {el, status, fixed, showState, StripChart} = sonibus;
  const HISTORY = 600;          // frames kept per robot for the charts (24 s at 25/s)
  const TOUCHED_MS = 1500;      // a slider the operator moved is left alone this long before it follows the robot
  const FINE_RAD = Math.PI / 1800;  // a slider's step for an angle: 0.1° (the arrow keys' move)
  // A joint's group is its chain, from the robot's info (Pepper's and NAO's, or those an installation names
  // in a ROS 2 robot's URDF); a joint in none is in "Joints". Legs and wheels get no slider (a slider
  // on them can topple or drive the robot): they are shown in "Body".
  const CHAIN_LABELS = {Head: "Head", LArm: "Left arm", RArm: "Right arm"};
  const BODY = new Set(["Leg", "LLeg", "RLeg", "Wheels"]);
  const STATES = {connected: "connected", connecting: "not connected: connecting", lost: "not connected: lost",
    not_answering: "not answering", standby: "standby: another owner keeps it"};  // (bus/connection.py)
  // What a robots message may change without the panel being built again (its state, not its controls).
  const LIVE = ["connected", "connection", "awareness", "activity", "controller"];

  function groupOf(joint) {
    if (!joint.chain) return "Joints";
    return BODY.has(joint.chain) ? "Body" : CHAIN_LABELS[joint.chain] || joint.chain;
  }

  /** A value with its unit (every value the page shows has one: radians, metres, as the robot says). */
  function withUnit(value, unit, digits = 3) {
    return `${fixed(value, digits)} ${unit}`;
  }

  function shortName(behavior) {
    return behavior.split("/").pop();
  }

  function stateOf(info) {
    return (info.connection || {}).state || (info.connected === false ? "lost" : "connected");
  }

  /** One robot: its summary line and its panel, its latest frame and its recent history.
      `page`: {command(robot, verb, args, done), note(what, ms), settings, redraw(), select(name)}. */
  class RobotView {
    /** Whether robots-message entries `a` and `b` give the same panel (they differ in state only). */
    static sameBuild(a, b) {
      const built = (info) => JSON.stringify({...info, ...Object.fromEntries(LIVE.map((key) => [key, undefined]))});
      return built(a) === built(b);
    }

    constructor(name, info, page) {
      this.name = name;
      this.info = info;
      this.page = page;
      this.joints = new Map(info.joints.map((joint) => [joint.name, joint]));
      this.values = new Map();         // joint → latest value
      this.times = new Float64Array(HISTORY);
      this.history = new Map(info.joints.map((joint) => [joint.name, new Float32Array(HISTORY)]));
      this.count = 0;                  // frames taken (the ring's write position is count % HISTORY)
      // The robot's rate, from its frames' own numbers and times (seq, t): the page gets the latest
      // frame update_hz times a second (25), so counting what it gets told the page's rate, not the
      // robot's. `pushed` counts those, shown only in the label's title, as the page's own.
      this.rate = {since: performance.now(), first: null, last: null, pushed: 0};
      this.touched = new Map();        // slider joint → when the operator last moved it
      this.throttle = new Map();       // slider joint → {last (ms), value, timer}
      this.awarenessAsked = null;      // the awareness the operator asked for, until the robot answers
      this.line = this.summary();
      this.section = this.build();
    }

    summary() {
      this.lineState = el("span", {class: "summary-state"});
      this.lineDoing = el("span", {class: "summary-doing"});
      this.lineSaying = el("span", {class: "summary-saying"});
      this.lineShow = el("span", {class: "summary-show"});
      this.lineRate = el("span", {class: "summary-rate"});
      return el("button", {type: "button", class: "summary-line", dataset: {summary: this.name},
        title: `show ${this.name}'s controls`, onclick: () => this.page.select(this.name)},
      el("b", {}, this.name), this.lineState, this.lineDoing, this.lineSaying, this.lineShow, this.lineRate);
    }

    build() {
      const joints = this.info.joints;
      this.cells = new Map();
      this.bars = new Map();
      this.sliders = new Map();
      this.behaviorButtons = new Map();
      const names = [...new Set(joints.map(groupOf))].sort((a, b) => (a === "Body") - (b === "Body"));  // (Body last)
      const groups = names.map((group) => [group, joints.filter((j) => groupOf(j) === group)]);
      this.connection = el("span", {class: "robot-connection"});
      this.rateLabel = el("span", {class: "robot-rate"});
      const header = el("header", {},
        el("h2", {}, this.name),
        el("span", {class: "robot-meta"}, `${this.info.model || "robot"} · ${this.info.owner || "no owner"}`),
        this.connection, this.rateLabel);
      // (one fieldset around them all: disabled, it disables every control inside while the robot is not connected)
      // only what the robot carries out (its info's verbs: a ROS 2 arm has no speech, behaviors nor awareness)
      const serves = new Set(this.info.verbs || ["behavior/run", "posture", "say", "awareness", "joints/set"]);
      const boxes = [["behavior/run", () => this.behaviorBox()], ["posture", () => this.postureBox()],
        ["say", () => this.sayBox()], ["awareness", () => this.awarenessBox()]];
      this.controls = el("fieldset", {class: "controls"},
        el("div", {class: "actions"}, ...boxes.filter(([verb]) => serves.has(verb)).map(([, box]) => box())),
        el("div", {class: "sliders"}, ...groups.filter(([group]) => group !== "Body" && serves.has("joints/set"))
          .map(([group, members]) => this.sliderBox(group, members))));
      this.charts = groups.map(([group, members]) => new StripChart(group, members, () => {
        this.fresh = true;
        this.page.redraw();
      }));
      const section = el("section", {class: "robot", dataset: {robot: this.name}}, header, this.controls,
        el("div", {class: "charts"}, ...this.charts.map((chart) => chart.figure)),
        el("div", {class: "joints"}, ...joints.map((joint) => this.jointRow(joint))));
      this.update(this.info);
      return section;
    }

    /** The robot's state from a robots message: connection, awareness, what it runs and says. */
    update(info) {
      this.info = info;
      const state = stateOf(info);
      const error = (info.connection || {}).error;
      // a ROS 2 robot whose trajectory controller is not matched: connected, but nothing it is sent arrives
      const unmatched = info.controller && !info.controller.matched && state === "connected";
      for (const label of [this.connection, this.lineState]) {
        label.textContent = unmatched ? "connected, controller not matched: commands reach nothing"
          : STATES[state] || state;
        label.title = unmatched ? info.controller.why : error || "";
        label.dataset.state = unmatched ? "unmatched" : state;
      }
      const usable = info.connected !== false && state === "connected";
      this.controls.disabled = !usable;
      this.controls.title = usable ? "" : `${this.name} is ${STATES[state] || state}: its controls wait for it (STOP works)`;
      this.showAwareness();
      const activity = info.activity || {behaviors: [], speaking: null};
      const running = activity.behaviors || [];
      // after a stop, until the robot carries out its next command (any but stop and behavior/list)
      const held = Boolean(activity.stopped) && !running.length;
      this.lineDoing.textContent = held ? "stopped — held still"
        : running.length ? `running ${running.map(shortName).join(", ")}` : "";
      this.lineDoing.title = held ? "a STOP holds it: its next command (a behavior, a posture, a slider, say) "
        + "resumes it" : running.join(", ");
      this.lineDoing.dataset.held = String(held);
      this.lineSaying.textContent = activity.speaking ? `saying “${activity.speaking}”` : "";
      this.lineSaying.title = activity.speaking || "";
      this.line.dataset.idle = String(!held && !running.length && !activity.speaking);
      // its show's state (<robot>/events/show), and when that changes next
      const show = activity.show;
      this.lineShow.textContent = show ? `show ${showState(show)}` : "";
      this.lineShow.dataset.state = show ? show.state : "";
      this.lineShow.title = show && show.state === "closed" && activity.resting
        ? "its show put it to rest, motors off: gestures are refused until it opens (or a supervisor wakes it)" : "";
      for (const name of running) {  // (a page opened while it runs: the server heard it start)
        const button = this.behaviorButtons.get(name);
        if (button && button.dataset.state === "idle") this.behaviorState(name, "started");
      }
    }

    /** Show this robot's panel (or hide it: another robot is selected). */
    show(shown) {
      this.section.hidden = !shown;
      this.line.setAttribute("aria-pressed", String(shown));
      if (shown) this.fresh = true;
    }

    jointRow(joint) {
      const cell = el("span", {class: "value", dataset: {joint: joint.name}}, "–");
      const bar = el("span", {class: "bar-fill"});
      this.cells.set(joint.name, cell);
      this.bars.set(joint.name, bar);
      return el("div", {class: "joint"}, el("span", {class: "name"}, joint.name), cell,
        el("span", {class: "unit"}, joint.unit),
        el("span", {class: "range-bar", title: `${fixed(joint.min, 2)} … ${withUnit(joint.max, joint.unit, 2)}`}, bar));
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
      return el("fieldset", {class: "say-box"}, el("legend", {}, "Say"), form);
    }

    awarenessBox() {
      const box = this.awareness = el("input", {type: "checkbox", dataset: {awareness: this.name},
        onchange: () => this.askAwareness(box.checked)});
      this.awarenessNote = el("small", {class: "note"});
      return el("fieldset", {class: "awareness"}, el("legend", {}, "Awareness"),
        el("label", {}, box, " look at people"), " ", this.awarenessNote);
    }

    /** The operator's click: shown at once, until the robot's answer (refused: back to its state). */
    askAwareness(enabled) {
      this.awarenessAsked = enabled;
      const sent = this.command("awareness", {enabled}, (reply) => {
        this.awarenessAsked = null;
        if (reply.ok) this.info = {...this.info, awareness: enabled};  // (its info says so too, when asked again)
        this.showAwareness();
        return false;
      });
      if (sent === null) this.awarenessAsked = null;
      this.showAwareness();
    }

    showAwareness() {
      if (!this.awareness) return;
      const known = typeof this.info.awareness === "boolean";
      const shown = this.awarenessAsked !== null ? this.awarenessAsked : this.info.awareness;
      this.awareness.indeterminate = this.awarenessAsked === null && !known;
      this.awareness.checked = shown === true;
      this.awareness.dataset.robotState = known ? String(this.info.awareness) : "unknown";
      this.awarenessNote.textContent = this.awarenessAsked !== null ? "asking…"
        : known ? (this.info.awareness ? "on" : "off") : "not said by its owner";
    }

    sliderBox(group, members) {
      return el("fieldset", {class: "slider-group", dataset: {group}}, el("legend", {}, group), ...members.map((joint) => {
        const angle = joint.unit === "rad";
        const output = el("output", {}, "–");
        const slider = el("input", {type: "range", min: joint.min, max: joint.max,
          step: angle ? FINE_RAD : Math.max((joint.max - joint.min) / 1000, 1e-6), value: (joint.min + joint.max) / 2,
          dataset: {slider: joint.name}, "aria-label": `${this.name} ${joint.name}`,
          title: `${joint.name} (${joint.unit}): drag, or ← → in steps of `
            + `${angle ? `${fixed(FINE_RAD, 4)} rad (0.1°)` : "a thousandth of its range"}`});
        const show = (value) => {
          output.textContent = withUnit(value, joint.unit);
        };
        slider.addEventListener("input", () => {
          this.touched.set(joint.name, performance.now());
          show(Number(slider.value));
          this.moveJoint(joint.name, Number(slider.value));
        });
        this.sliders.set(joint.name, {slider, show});
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
      this.rate.pushed += 1;
      if (this.rate.first === null || frame.seq < this.rate.last.seq) this.rate.first = frame;  // (a restart: seq anew)
      this.rate.last = frame;
      this.fresh = true;
    }

    render(now) {
      if (now - this.rate.since >= 1000) {
        const {first, last, pushed, since} = this.rate;
        const span = first && last ? last.t - first.t : 0;
        const hz = span > 0 ? (last.seq - first.seq) / span : 0;  // (no frame for a second: 0, not the last figure)
        this.rate = {since: now, first: last, last, pushed: 0};
        this.rateLabel.textContent = this.lineRate.textContent = `${hz.toFixed(0)} frames/s`;
        this.rateLabel.title = this.lineRate.title =
          `the robot's frames per second (this page draws ${(pushed * 1000 / (now - since)).toFixed(0)} of them a second)`;
      }
      if (!this.fresh || this.section.hidden) return false;  // (a hidden panel is drawn when shown)
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
          control.show(value);
        }
      }
      for (const chart of this.charts) chart.draw(this.times, this.history, this.count);
      return true;
    }
  }

  sonibus.RobotView = RobotView;
})();
