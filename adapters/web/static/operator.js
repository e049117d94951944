/* The operator page: a summary line per robot at the top (its state, what it runs and
   says; a click shows that robot's panel, one at a time: robot.js), redrawn on
   requestAnimationFrame when frames came, the nodes and their stats, the event log
   (repeats folded into one line, ×N), every reply in the status line, and STOP
   (button, Space, Escape). Protocol: docs/web.md. */
"use strict";

(() => {
  const {el, status, fixed, Link, RobotView} = sonibus;
  const EVENTS_KEPT = 200;      // entries of the event log
  const TRACE_KEPT = 1000;      // round trips kept for a bench
  const AMBER_MS = 5000;        // a node stays amber this long after a loss counter moved
  const LOSS_COUNTERS = ["dropped", "stale", "bad", "errors"];  // every node has them (node_stats)

  const settings = {update_hz: 25, slider_hz: 20, speed: 0.2};
  const views = new Map();       // robot name → RobotView
  let selected = decodeURIComponent(location.hash.slice(1)) || null;  // the robot whose panel is shown
  const counters = {frames: 0, rendered: 0, render_ms: 0, events: 0, stats: 0};
  const trace = [];              // {what, ms}: a behavior click until its reply, until it shows running (bench/web_page.py)
  let dirty = false;

  function note(what, ms) {
    trace.push({what, ms});
    if (trace.length > TRACE_KEPT) trace.splice(0, trace.length - TRACE_KEPT);
  }

  // -- what the server sends ------------------------------------------------------

  function onHello(message) {
    for (const key of Object.keys(settings)) {
      if (Number.isFinite(message[key])) settings[key] = message[key];
    }
  }

  function onRobots(message) {
    const container = document.getElementById("robots");
    const lines = document.getElementById("summary");
    const robots = message.robots || {};
    for (const [name, view] of views) {
      if (!(name in robots)) {
        view.section.remove();
        view.line.remove();
        views.delete(name);
      }
    }
    for (const name of Object.keys(robots).sort()) {
      const info = {joints: [], ...robots[name]};
      const view = views.get(name);
      if (view && RobotView.sameBuild(view.info, info)) {
        view.update(info);
        continue;
      }
      const fresh = new RobotView(name, info, page);
      if (view) {
        view.section.replaceWith(fresh.section);
        view.line.replaceWith(fresh.line);
      } else {
        container.append(fresh.section);
        lines.append(fresh.line);
      }
      views.set(name, fresh);
    }
    container.classList.toggle("empty", views.size === 0);
    select(views.has(selected) ? selected : [...views.keys()].sort()[0]);
    dirty = true;
  }

  /** Show robot `name`'s panel, the others' summary lines only (kept in the URL's #: a reload keeps it). */
  function select(name) {
    if (name === undefined) return;
    selected = name;
    for (const [other, view] of views) view.show(other === name);
    const hash = `#${encodeURIComponent(name)}`;
    if (location.hash !== hash) history.replaceState(null, "", hash);
    dirty = true;
  }

  function onFrame(message) {
    counters.frames += 1;
    const view = views.get(message.robot);
    if (!view || !Array.isArray(message.names) || !Array.isArray(message.v)) return;
    view.take(message);
    dirty = true;
  }

  /** What tells an event from the one before in the log: all of it but its time, and but the
      angles and speed of a joints/set (a slider's moves fold into one line). */
  function sameAs(message) {
    const {t, ...event} = message.event || {};
    if (message.kind === "command" && event.verb === "joints/set") {
      const {angles, speed, ...args} = event.args || {};
      event.args = args;
    }
    return JSON.stringify([message.robot, message.kind, event]);
  }

  function onEvent(message) {
    counters.events += 1;
    const event = message.event || {};
    const view = views.get(message.robot);
    if (view && message.kind === "behavior" && event.name) view.behaviorState(event.name, event.state, event.error);
    const log = document.getElementById("events");
    const when = new Date((event.t || Date.now() / 1000) * 1000).toLocaleTimeString([], {hour12: false});
    const details = Object.entries(event).filter(([key]) => key !== "t" && key !== "kind")
      .map(([key, value]) => `${key}=${typeof value === "string" ? value : JSON.stringify(value)}`).join(" ");
    const same = sameAs(message);
    const last = log.firstElementChild;
    if (last && last.same === same) {  // the same again (a slider's moves): one line, ×N, the latest shown
      const times = Number(last.dataset.times) + 1;
      last.dataset.times = String(times);
      last.querySelector("time").textContent = when;
      last.querySelector(".details").textContent = details;
      last.querySelector(".times").textContent = `×${times}`;
      return;
    }
    const failed = event.state === "failed" || event.ok === false;
    const line = el("li", {class: failed ? "failed" : "", dataset: {kind: message.kind, times: "1"}},
      el("time", {}, when), el("b", {}, `${message.robot || "sonibus"} ${message.kind}`), " ",
      el("span", {class: "details"}, details), " ", el("span", {class: "times"}));
    line.same = same;
    log.prepend(line);
    while (log.children.length > EVENTS_KEPT) log.lastElementChild.remove();
  }

  const lossSeen = new Map();   // "host/node" → {counts, moved (ms)}

  function onStats(message) {
    counters.stats += 1;
    const now = performance.now();
    const body = document.querySelector("#nodes tbody");
    const rows = (message.nodes || []).slice().sort((a, b) =>
      `${a.host}/${a.node}`.localeCompare(`${b.host}/${b.node}`));
    body.replaceChildren(...rows.map((node) => {
      const name = `${node.host}/${node.node}`;
      const counts = node.counters || {};
      const losses = LOSS_COUNTERS.map((key) => counts[key] || 0);
      const seen = lossSeen.get(name);
      const moved = seen && losses.some((value, i) => value > seen.counts[i]) ? now : (seen ? seen.moved : -Infinity);
      lossSeen.set(name, {counts: losses, moved});
      const state = node.gone ? "gone" : (now - moved < AMBER_MS ? "warning" : "ok");
      const rates = node.rates || {};
      const latency = node.latency_ms ? `${fixed(node.latency_ms.p99, 1)} ms` : "";
      const process = node.process || {};
      return el("tr", {class: state, dataset: {node: name, state}},
        el("th", {scope: "row", title: node.adapter || ""}, name),
        el("td", {}, node.gone ? "gone" : node.state || ""),
        el("td", {class: "num"}, `${fixed(rates.received || 0, 0)}/s`),
        el("td", {class: "num"}, `${fixed(rates.sent || 0, 0)}/s`),
        el("td", {class: "num", title: LOSS_COUNTERS.join(", ")},
          LOSS_COUNTERS.filter((key) => counts[key]).map((key) => `${key} ${counts[key]}`).join(" ") || "0"),
        el("td", {class: "num"}, latency),
        el("td", {class: "num"}, Number.isFinite(process.cpu_percent) ? `${fixed(process.cpu_percent, 0)} %` : ""));
    }));
  }

  // -- what the operator sends ----------------------------------------------------

  /** Send `verb` with `args` to `robot`; the reply shows in the status line. The id, or null. */
  function command(robot, verb, args, done) {
    return link.send({type: "command", robot, verb, args: args || {}}, `${robot} ${verb}`, done);
  }

  function stopAll() {
    const stop = document.getElementById("stop");
    stop.classList.remove("pressed");
    void stop.offsetWidth;
    stop.classList.add("pressed");
    for (const view of views.values()) view.dropHeldMoves();  // nothing of this page moves a robot after a stop
    const answers = [];  // one reply per robot on the bus
    const sent = link.send({type: "stop"}, "stop", (reply) => {
      if (!reply.robot && !reply.robots) return false;  // ("stop: no robot on the bus": shown as it is)
      const unreached = reply.ok && reply.result && reply.result.reached === false;  // taken, but not carried out
      if (reply.robots) answers.push(`✗ ${reply.error}`);  // (those on the bus that did not answer, in one)
      else answers.push(reply.ok && !unreached ? `✓ ${reply.robot}`
        : `✗ ${reply.robot}: ${unreached ? `not reached: ${reply.result.error}` : reply.error || "refused"}`);
      status(`STOP: ${answers.join(", ")}`, answers.some((a) => a.startsWith("✗")) ? "error" : "ok");
      return true;
    });
    if (sent !== null) status("STOP sent to every robot", "info");
  }

  function typing(target) {
    return target instanceof HTMLElement
      && (target.isContentEditable || target.tagName === "TEXTAREA"
          || (target.tagName === "INPUT" && !["range", "checkbox", "button", "submit"].includes(target.type)));
  }

  document.addEventListener("keydown", (event) => {
    if (event.key === "Escape") {
      event.preventDefault();
      if (!event.repeat) stopAll();
    } else if ((event.key === " " || event.code === "Space") && !typing(event.target)) {
      event.preventDefault();  // not the focused button's click, not a scroll
      if (!event.repeat) stopAll();
    }
  });
  document.addEventListener("keyup", (event) => {
    if ((event.key === " " || event.code === "Space") && !typing(event.target)) event.preventDefault();
  });
  document.getElementById("stop").addEventListener("click", stopAll);

  function frameLoop(now) {
    if (dirty) {
      const began = performance.now();
      dirty = false;
      let drawn = false;
      for (const view of views.values()) drawn = view.render(now) || drawn;
      if (drawn) {
        counters.rendered += 1;
        counters.render_ms += performance.now() - began;
      }
    } else {
      for (const view of views.values()) view.render(now);
    }
    requestAnimationFrame(frameLoop);
  }

  const page = {command, note, settings, select, redraw: () => { dirty = true; }};
  const link = new Link("/ws", {
    hello: onHello, robots: onRobots, frame: onFrame, event: onEvent, stats: onStats,
  });
  requestAnimationFrame(frameLoop);

  // For tests and bench/web_page.py: what the page counted, and a way to send as the page does.
  Object.assign(sonibus, {link, counters, trace, settings, command, select, stop: stopAll});
})();
