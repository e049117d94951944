// The official Foxglove WebSocket client (@foxglove/ws-protocol's FoxgloveClient over the
// `ws` package), as Lichtblick and older Foxglove apps use it: it offers only its constant
// subprotocol, foxglove.websocket.v1. Run by tests/foxglove/test_official_client.py:
//
//   node client.js ws://127.0.0.1:8765 TOPIC_REGEX [SESSIONS]
//
// Each session connects, subscribes to every advertised channel whose topic matches as soon
// as it is advertised (as a panel does), and prints one JSON line per event: open (with the
// subprotocol agreed), advertise, unadvertise, message (topic and text), status, close. As
// Lichtblick does, it unsubscribes from a channel that is unadvertised (and subscribes again
// when its topic is advertised anew). A line on stdin ends the session; the next one connects.
// It exits after SESSIONS sessions (default 1). With SUBSCRIBE_LATER=1 in its environment it
// holds its subscriptions until a line "subscribe" on stdin (a viewer that subscribes a moment
// after it hears of a channel, made deterministic for a test).
"use strict";

const readline = require("readline");
const WebSocket = require("ws");
const { FoxgloveClient } = require("@foxglove/ws-protocol");

const [url, pattern, sessions = "1"] = process.argv.slice(2);
const topics = new RegExp(pattern);
const decoder = new TextDecoder();
const say = (event) => process.stdout.write(JSON.stringify(event) + "\n");
const lines = readline.createInterface({ input: process.stdin });
const waiting = [];
const later = process.env.SUBSCRIBE_LATER === "1";
let held = [];
lines.on("line", (line) => {
  if (line === "subscribe") {
    const due = held;
    held = [];
    due.forEach((subscribe) => subscribe());
  } else {
    (waiting.shift() || (() => {}))();
  }
});

function session(index) {
  return new Promise((resolve) => {
    const ws = new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
    const client = new FoxgloveClient({ ws });
    const bySubscription = new Map();
    client.on("open", () => say({ ev: "open", session: index, protocol: ws.protocol }));
    client.on("serverInfo", (info) => say({ ev: "serverInfo", ...info }));
    client.on("advertise", (channels) => {
      for (const channel of channels) {
        say({ ev: "advertise", topic: channel.topic, id: channel.id });
        if (topics.test(channel.topic)) {
          const subscribe = () =>
            bySubscription.set(client.subscribe(channel.id), { id: channel.id, topic: channel.topic });
          if (later) held.push(subscribe);
          else subscribe();
        }
      }
    });
    client.on("unadvertise", (ids) => {
      say({ ev: "unadvertise", ids });
      for (const [subscription, channel] of bySubscription) {
        if (ids.includes(channel.id)) {
          client.unsubscribe(subscription);
          bySubscription.delete(subscription);
        }
      }
    });
    client.on("message", ({ subscriptionId, data, timestamp }) => {
      const channel = bySubscription.get(subscriptionId);
      say({ ev: "message", topic: channel && channel.topic, text: decoder.decode(data),
            logTime: String(timestamp) });
    });
    client.on("status", (status) => say({ ev: "status", level: status.level, message: status.message }));
    client.on("error", (error) => say({ ev: "error", message: String(error && error.message) }));
    client.on("close", (event) => {
      say({ ev: "close", code: event.code });
      resolve();
    });
    waiting.push(() => client.close());
  });
}

(async () => {
  for (let i = 0; i < Number(sessions); i++) {
    await session(i);
  }
  lines.close();
})();
