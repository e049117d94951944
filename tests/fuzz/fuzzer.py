"""Sends ``Input``s to a running ``Show`` and keeps count: a Zenoh session of its
own (puts and queries), a UDP socket to the OSC gateway (its replies read back),
a subscriber on ``pepper/events/command`` feeding the ``Oracle``, and queryables
for the ghost robots whose info replies are garbage."""

from __future__ import annotations

import contextlib
import socket
import threading
import time
from collections import Counter, defaultdict
from typing import Any

import msgpack
import zenoh

from .families import GHOSTS, ROBOT, VALID, Input, Oracle, ghost_reply, signature
from .show import Show

QUERY_TIMEOUT_S = 5.0
BURST_RATE = 5000  # inputs per second at most in a burst


class Fuzzer:
    def __init__(self, show: Show) -> None:
        self.show = show
        self.session = show.session
        self.oracle = Oracle()
        self.tried: dict[str, Counter[str]] = defaultdict(Counter)   # family → label → inputs
        self.outcomes: dict[str, Counter[str]] = defaultdict(Counter)  # family → reply code / refusal
        self.first: dict[str, Input] = {}  # the first input of each family/label/note, for reproductions
        self.events: list[dict[str, Any]] = []
        self._lock = threading.Lock()
        self._subscriber = self.session.declare_subscriber(f"{ROBOT}/events/command", self._take_event)
        self._ghosts = [self.session.declare_queryable(f"ghost{i}/info", self._ghost(i)) for i in range(GHOSTS)]
        self.ghost_queries: Counter[int] = Counter()
        self.osc = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.osc.bind(("127.0.0.1", 0))
        self.osc.settimeout(0.2)
        self.osc_replies: Counter[str] = Counter()
        self.tokens: list[Any] = []  # claims held until ``release``
        self._done = threading.Event()
        self._reader = threading.Thread(target=self._read_replies, daemon=True)
        self._reader.start()

    # -- receiving ----------------------------------------------------------------------------

    def _take_event(self, sample: zenoh.Sample) -> None:
        try:
            event = msgpack.unpackb(sample.payload.to_bytes(), raw=False)
        except Exception:
            event = {"undecodable": sample.payload.to_bytes()[:64]}
        with self._lock:
            self.events.append(event)
            if isinstance(event, dict):
                self.oracle.event(event)

    def _ghost(self, index: int) -> Any:
        def reply(query: zenoh.Query) -> None:
            self.ghost_queries[index] += 1
            query.reply(f"ghost{index}/info", ghost_reply(index))
        return reply

    def _read_replies(self) -> None:
        while not self._done.is_set():
            try:
                data, _ = self.osc.recvfrom(65536)
            except (TimeoutError, OSError):
                continue
            address = data.split(b"\0", 1)[0].decode("latin-1")
            ok = b",is" in data[:64] and b"\0\0\0\x01" in data
            self.osc_replies[f"{address} {'ok' if ok else 'refused'}"] += 1

    # -- sending ------------------------------------------------------------------------------

    def send(self, item: Input) -> None:
        """Send one input (a query waits for its replies)."""
        with self._lock:
            self.oracle.sent(item)
        self.tried[item.family][item.label] += 1
        self.first.setdefault(f"{item.family}/{item.label}/{item.note}", item)
        if item.how in ("put", "ghost"):
            self._put(item)
        elif item.how == "token":
            self._token(item)
        elif item.how == "query":
            self._query(item)
        else:
            self.osc.sendto(item.payload, ("127.0.0.1", self.show.ports.gateway))

    def burst(self, item: Input | list[Input], count: int) -> float:
        """``item`` ``count`` times (or each of a list in turn) at up to ``BURST_RATE`` a second;
        the rate reached."""
        items = item if isinstance(item, list) else [item]
        started = time.perf_counter()
        for n in range(count):
            self.send(items[n % len(items)])
            ahead = n / BURST_RATE - (time.perf_counter() - started)
            if ahead > 0.002:
                time.sleep(ahead)
        return count / max(time.perf_counter() - started, 1e-9)

    def _put(self, item: Input) -> None:
        try:
            self.session.put(item.key, item.payload)
        except zenoh.ZError as exc:  # a key Zenoh itself refuses never reaches a node
            self.outcomes[item.family][f"zenoh refused: {str(exc)[:60]}"] += 1

    def _token(self, item: Input) -> None:
        try:
            self.tokens.append(self.session.liveliness().declare_token(item.key))
        except zenoh.ZError as exc:  # a key Zenoh itself refuses never reaches a node
            self.outcomes[item.family][f"zenoh refused: {str(exc)[:60]}"] += 1

    def release(self) -> None:
        """Withdraw every claim ``send`` declared."""
        for token in self.tokens:
            with contextlib.suppress(Exception):
                token.undeclare()
        self.tokens.clear()

    def stop(self) -> str:
        """``stop`` to pepper, as any asker sends it (a valid command): "ok", or what came instead."""
        with self._lock:
            self.oracle.sent(Input("command", VALID, "query", f"{ROBOT}/cmd/stop", b"", signature("stop", {})))
        replies = [r for r in self.session.get(f"{ROBOT}/cmd/stop", timeout=QUERY_TIMEOUT_S) if r.ok is not None]
        answers = [msgpack.unpackb(r.ok.payload.to_bytes(), raw=False) for r in replies]
        return "ok" if any(a.get("ok") for a in answers if isinstance(a, dict)) else f"no ok among {answers}"

    def _query(self, item: Input) -> None:
        try:
            replies = list(self.session.get(item.key, payload=item.payload or None, timeout=QUERY_TIMEOUT_S))
        except zenoh.ZError as exc:
            self.outcomes[item.family][f"zenoh refused: {str(exc)[:60]}"] += 1
            return
        if not replies:
            self.outcomes[item.family]["no reply"] += 1
        for reply in replies:
            if reply.ok is None:
                self.outcomes[item.family]["error reply"] += 1
                continue
            try:
                answer = msgpack.unpackb(reply.ok.payload.to_bytes(), raw=False)
            except Exception:
                self.outcomes[item.family]["undecodable reply"] += 1
                continue
            if item.family == "command" and isinstance(answer, dict):
                code = "ok" if answer.get("ok") else (answer.get("error") or {}).get("code", "?")
                self.outcomes[item.family][str(code)] += 1
            else:
                self.outcomes[item.family]["answered"] += 1

    def settle(self, quiet_s: float = 0.5, timeout: float = 10.0) -> None:
        """Until no command event came for ``quiet_s`` (the last commands announced)."""
        deadline = time.monotonic() + timeout
        seen, since = len(self.events), time.monotonic()
        while time.monotonic() < deadline:
            time.sleep(0.05)
            if len(self.events) != seen:
                seen, since = len(self.events), time.monotonic()
            elif time.monotonic() - since >= quiet_s:
                return

    def close(self) -> None:
        self.release()
        self._done.set()
        self._reader.join(1.0)
        self.osc.close()
        for entity in (self._subscriber, *self._ghosts):
            with contextlib.suppress(Exception):
                entity.undeclare()
