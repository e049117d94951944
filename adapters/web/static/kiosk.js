/* The kiosk page for visitors: only the buttons the installation lists (from
   `hello`), big touch targets, one scenario at a time; each button shows
   "running" then "done" from the server's `button` messages. It can only
   `press`: no other control exists in this page. Visitors see nothing of the
   operator's: no status line, no replies, no connection banner; while the page
   is not connected, "One moment, please…" and the buttons disabled (the reason
   goes to the console). While the robot's show is closed: "closed, opens Sun 10:00" and the
   buttons dimmed. Protocol: docs/web.md. */
"use strict";

(() => {
  const {el, withToken, showState, Link} = sonibus;
  const SHOWN = {idle: "", running: "running…", done: "done", failed: "sorry, not now"};  // (for visitors)
  const buttons = new Map();   // id → button element
  let waiting = null;          // the id of a press not yet answered
  let shown = "";              // the buttons of the last hello, as JSON
  let closed = false;          // the robot's show is closed: the buttons are dimmed, the next opening said

  function onHello(message) {
    const container = document.getElementById("buttons");
    const wanted = JSON.stringify(message.buttons || []);
    if (shown === wanted) return;  // a reconnection: the same buttons, states kept
    shown = wanted;
    buttons.clear();
    container.replaceChildren(...(message.buttons || []).map((spec) => {
      const button = el("button", {type: "button", class: "kiosk-button", dataset: {button: spec.id, state: "idle"},
        onclick: () => press(spec.id)},
      spec.image ? el("img", {src: withToken(spec.image), alt: ""}) : null,
      el("span", {class: "label"}, spec.label || spec.id),
      el("span", {class: "state"}));
      buttons.set(spec.id, button);
      return button;
    }));
    if (!buttons.size) container.append(el("p", {class: "placeholder"}, "No buttons are configured."));
    refresh();
  }

  function onButton(message) {
    const button = buttons.get(message.id);
    if (!button) return;
    const state = message.state in SHOWN ? message.state : "idle";
    button.dataset.state = state;
    button.querySelector(".state").textContent = SHOWN[state];
    button.title = message.error || "";
    refresh();
  }

  function onShow(message) {
    closed = message.state === "closed";
    const line = document.getElementById("show");
    line.textContent = closed ? showState(message) : "";
    line.hidden = !closed;
    document.body.classList.toggle("closed", closed);
    refresh();
  }

  function press(id) {
    if (waiting !== null || running()) return;
    waiting = link.send({type: "press", button: id}, buttons.get(id).querySelector(".label").textContent,
      () => { waiting = null; refresh(); });
    refresh();
  }

  function running() {
    return [...buttons.values()].some((button) => button.dataset.state === "running");
  }

  /** One scenario at a time: every button is disabled while one runs or a press is unanswered. */
  function refresh() {
    const busy = waiting !== null || running() || !link.connected || closed;
    for (const button of buttons.values()) button.disabled = busy;
    document.body.classList.toggle("busy", busy);
  }

  document.addEventListener("contextmenu", (event) => event.preventDefault());  // a long press on a touchscreen
  function onConnection(connected) {
    if (!connected) waiting = null;  // a press the link lost is never answered
    document.getElementById("notice").hidden = connected;
    refresh();
  }

  const link = new Link("/kiosk/ws", {hello: onHello, button: onButton, show: onShow,
    connection: onConnection});
  Object.assign(sonibus, {link});
})();
