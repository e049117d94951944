/* sonibus pages, shared: the WebSocket link to the web node (the page's ?token=
   passed on, reconnected with backoff, "disconnected" shown), requests with ids
   and their replies, and the status line where every reply is shown.
   Plain script, no build step: it defines the global `sonibus`. */
"use strict";

const sonibus = (() => {
  const token = new URLSearchParams(location.search).get("token") || "";
  const BACKOFF_MS = [250, 500, 1000, 2000, 4000, 5000];  // then 5 s, until the server is back
  const PENDING_MS = 30000;  // a request's description is kept this long for its replies (stop has one per robot)

  /** The URL of `path` on this server, with the page's token (for images, links). */
  function withToken(path) {
    if (!token || /^[a-z]+:/i.test(path)) return path;
    return path + (path.includes("?") ? "&" : "?") + "token=" + encodeURIComponent(token);
  }

  function socketUrl(path) {
    const scheme = location.protocol === "https:" ? "wss:" : "ws:";
    return scheme + "//" + location.host + withToken(path);
  }

  /** `value` with `digits` decimals, or "–" when it is no number. */
  function fixed(value, digits) {
    return Number.isFinite(value) ? value.toFixed(digits) : "–";
  }

  /** `el("button", {class: "x", dataset: {behavior: "wave"}}, "text", child)` */
  function el(tag, attributes, ...children) {
    const node = document.createElement(tag);
    for (const [name, value] of Object.entries(attributes || {})) {
      if (name === "dataset") Object.assign(node.dataset, value);
      else if (name === "class") node.className = value;
      else if (name.startsWith("on")) node.addEventListener(name.slice(2), value);
      else if (value !== undefined && value !== null && value !== false) node.setAttribute(name, value === true ? "" : value);
    }
    for (const child of children) {
      if (child !== null && child !== undefined) node.append(child);
    }
    return node;
  }

  /** The status line (#status): the latest reply or notice; `kind` is ok, error or info. */
  function status(text, kind = "info") {
    const line = document.getElementById("status");
    if (!line || (line.textContent === text && line.dataset.kind === kind)) return;  // (a slider's replies: no flicker)
    line.textContent = text;
    line.dataset.kind = kind;
    line.classList.remove("flash");
    void line.offsetWidth;  // restart the flash animation
    line.classList.add("flash");
  }

  /** The WebSocket to the web node: `on[type](message)` for each message it sends. */
  class Link {
    constructor(path, on) {
      this.path = path;
      this.on = on;
      this.ws = null;
      this.connected = false;
      this.nextId = 1;
      this.pending = new Map();   // id → {what, sent (ms), done(reply)}
      this.attempt = 0;
      this.counters = {messages: 0, replies: 0, bad: 0, reconnects: 0};
      this.open();
    }

    open() {
      const ws = new WebSocket(socketUrl(this.path));
      this.ws = ws;
      ws.onmessage = (event) => this.receive(event.data);
      ws.onclose = () => { if (this.ws === ws) this.lost(); };
      ws.onerror = () => {};  // onclose follows and says it
    }

    lost() {
      this.ws = null;
      const delay = BACKOFF_MS[Math.min(this.attempt, BACKOFF_MS.length - 1)];
      this.attempt += 1;
      this.counters.reconnects += 1;
      this.state(false, `disconnected — reconnecting in ${(delay / 1000).toFixed(delay < 1000 ? 2 : 0)} s`);
      setTimeout(() => this.open(), delay);
    }

    state(connected, text) {
      this.connected = connected;
      document.body.classList.toggle("disconnected", !connected);
      const banner = document.getElementById("connection");
      if (banner) {
        banner.textContent = text;
        banner.dataset.state = connected ? "connected" : "disconnected";
      } else if (!connected) {
        console.warn(`sonibus: ${text}`);  // (a page without the banner, the kiosk: said where an operator looks)
      }
      if (this.on.connection) this.on.connection(connected);
    }

    receive(data) {
      let message;
      try {
        message = JSON.parse(data);
      } catch (error) {
        this.counters.bad += 1;
        return;
      }
      this.counters.messages += 1;
      if (message.type === "hello") {
        this.attempt = 0;
        this.state(true, "connected");
      }
      if (message.type === "reply") this.reply(message);
      const handler = this.on[message.type];
      if (handler) handler(message);
    }

    /** Send `message` (an id is given when it has none); `what` names it in the status line.
        `done(reply, ms)` gets each reply first; when it returns true it has shown the reply itself. */
    send(message, what, done) {
      if (!this.ws || this.ws.readyState !== WebSocket.OPEN) {
        status(`not connected: ${what} not sent`, "error");
        return null;
      }
      const id = message.id || this.nextId++;
      this.pending.set(id, {what, sent: performance.now(), done});
      this.ws.send(JSON.stringify({...message, id}));
      this.prune();
      return id;
    }

    reply(message) {
      this.counters.replies += 1;
      const request = this.pending.get(message.id);
      if (request && request.done && request.done(message, performance.now() - request.sent) === true) return;
      let what = request ? request.what : `request ${message.id}`;
      if (message.robot && !what.startsWith(message.robot + " ")) what = `${message.robot} ${what}`;
      if (message.ok) {
        status(`✓ ${what}`, "ok");
      } else {
        const error = message.error || "refused";
        const head = error.split(":")[0];  // an owner's error may start with the verb: said once
        status(what.endsWith(" " + head) ? `✗ ${what.slice(0, -head.length)}${error}` : `✗ ${what}: ${error}`, "error");
      }
    }

    prune() {
      const old = performance.now() - PENDING_MS;
      for (const [id, request] of this.pending) {
        if (request.sent >= old) break;  // a Map keeps insertion order: the rest are newer
        this.pending.delete(id);
      }
    }
  }

  /** A show's state as a line: "closed, opens Sun 10:00", "open, closes Tue 18:00" (the wall clock
      of the show's own zone: read from its ISO text, not converted to the browser's). */
  function showState(show) {
    const when = /^(\d{4})-(\d{2})-(\d{2})T(\d{2}:\d{2})/.exec(show.next || "");
    if (!when) return show.state;
    const day = ["Sun", "Mon", "Tue", "Wed", "Thu", "Fri", "Sat"][
      new Date(Date.UTC(+when[1], +when[2] - 1, +when[3])).getUTCDay()];
    return `${show.state}, ${show.state === "closed" ? "opens" : "closes"} ${day} ${when[4]}`;
  }

  return {token, withToken, el, fixed, status, showState, Link};
})();
