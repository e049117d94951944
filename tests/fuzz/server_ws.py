"""The ``websocket`` family: what a broken or hostile WebSocket client sends the show's three
servers. Generated (Hypothesis), on a connection kept while the server keeps it: bad frames
(reserved opcodes and bits, unmasked, control frames too long or fragmented, orphan
continuations, invalid UTF-8, bad close codes, lengths past the cap), fragmented and huge
messages, and each server's protocol messages, bad (not JSON, deep, unknown ops, wrong types)
and valid. Scripted after them, at the three servers at once: floods of valid and invalid
messages, subscribe and LISTEN floods, clients that never read, clients past the cap.

After each input a probe the server must answer (an unknown message with an id, ``/?HOST_INFO``,
an unsubscribe of nothing) tells whether it kept the connection (``kept``) or closed it (its
close code): one or the other within ``ANSWER_S``, else it hangs (a problem). Valid commands
sent to the web page are told to the oracle (they may run); nothing else may.
"""

from __future__ import annotations

import json
import socket
import struct
import threading
import time
from typing import TYPE_CHECKING

from hypothesis import strategies as st

from .families import VALID, Input, signature
from .serving import BINARY, CLIENTS, CLOSE, PING, SERVERS, TEXT, RawWs, frame, port

if TYPE_CHECKING:
    from .checks import Report
    from .fuzzer import Fuzzer

FAMILY = "websocket"
MAX_MESSAGE = 1 << 20  # bytes of one message the three servers take (aiohttp's max_msg_size): past it, 1009
PROBE = {"web": '{"type": "probe", "id": "fuzz-probe"}', "oscquery": "/?HOST_INFO",
         "foxglove": '{"op": "unsubscribe", "subscriptionIds": [4294967295]}'}
PROBED = {"web": b'"fuzz-probe"', "oscquery": b'"OSC_PORT"', "foxglove": b"4294967295"}
FLOOD = 400            # messages of each kind in a flood
NEVER_READ_S = 1.0     # how long a client that never reads stays before it vanishes
JOINTS = ["HeadYaw", "HeadPitch", "LShoulderPitch", "RShoulderPitch", "LHand", "RHand"]


def _messages(server: str) -> st.SearchStrategy[tuple[str, str, str | None]]:
    """``(kind, text, runs)`` of ``server``'s protocol: ``runs``, the verb of a command it may run
    (told to the oracle), else None."""
    common = st.one_of(
        st.sampled_from([("not json", "{nope", None), ("not json", "", None), ("not json", "\ufeff{}", None),
                         ("deep", "[" * 100_000, None), ("deep", '{"a":' * 50_000, None),
                         ("not an object", "[1, 2, 3]", None), ("not an object", "null", None),
                         ("not an object", '"x"', None), ("nan", '{"x": NaN, "id": Infinity}', None),
                         ("huge string", '{"x": "' + "y" * 70_000 + '"}', None)]),
        st.text(max_size=40).map(lambda t: ("text", t, None)))
    if server == "web":
        command = st.fixed_dictionaries({
            "type": st.just("command"), "id": st.one_of(st.integers(), st.text(max_size=8), st.none()),
            "robot": st.sampled_from(["pepper", "*", "**", "pepper/cmd", "", "ghost0", "nobody", "a" * 300]),
            "verb": st.sampled_from(["say", "joints/set", "dance", "stiffness", "", "cmd/say", "behavior/run/x"]),
            "args": st.sampled_from([{"text": 5}, {"names": ["NoSuchJoint"], "angles": [0.1]},
                                     {"names": ["HeadYaw"], "angles": [100.0]}, {"names": ["Body"], "value": 7.0},
                                     {"names": ["HeadYaw"], "angles": [float("nan")]}, [], "x", {"name": 5}])})
        own = st.one_of(
            command.filter(lambda c: c["robot"] != "pepper" or c["verb"] != "say")
                   .map(lambda c: ("bad command", json.dumps(c), None)),
            st.sampled_from([("unknown type", '{"type": "dance", "id": 1}', None),
                             ("press", '{"type": "press", "id": 2, "button": "x"}', None),
                             ("no type", '{"id": 3}', None), ("id", '{"type": "stop", "id": [1]}', "stop"),
                             ("valid", '{"type": "command", "id": 4, "robot": "pepper", "verb": "behavior/list"}',
                              "behavior/list")]))
    elif server == "oscquery":
        path = st.one_of(st.sampled_from([f"/pepper/joints/{j}" for j in JOINTS] + ["/pepper", "/", "/nobody/x"]),
                         st.text(max_size=30), st.just("/" + "p" * 2000), st.just("/a b"), st.just("/a#b"))
        own = st.one_of(
            st.tuples(st.sampled_from(["LISTEN", "IGNORE", "listen", "PATH_ADDED", ""]),
                      st.one_of(path, st.integers(), st.none(), st.lists(st.text(max_size=3), max_size=2)))
              .map(lambda c: ("command", json.dumps({"COMMAND": c[0], "DATA": c[1]}), None)),
            path.map(lambda p: ("query", p + "?VALUE", None)),
            st.sampled_from([("query", "/pepper/joints/HeadYaw?NOPE", None), ("query", "/?HOST_INFO", None),
                             ("long", "/" + "x" * 5000, None)]))
    else:
        ids = st.one_of(st.integers(0, 64), st.integers(2**32 - 2, 2**32 + 2), st.integers(-5, -1), st.booleans(),
                        st.floats(allow_nan=False, max_value=10), st.text(max_size=3), st.none())
        own = st.one_of(
            st.lists(st.fixed_dictionaries({"id": ids, "channelId": ids}), max_size=8)
              .map(lambda s: ("subscribe", json.dumps({"op": "subscribe", "subscriptions": s}), None)),
            st.lists(ids, max_size=8).map(lambda i: ("unsubscribe", json.dumps({"op": "unsubscribe",
                                                                                   "subscriptionIds": i}), None)),
            st.sampled_from(["advertise", "unadvertise", "getParameters", "setParameters",
                             "subscribeParameterUpdates", "subscribeConnectionGraph", "fetchAsset", "serverInfo",
                             "", "SUBSCRIBE"]).map(lambda op: ("unknown op", json.dumps({"op": op}), None)),
            st.sampled_from([("fields", '{"op": "subscribe"}', None),
                             ("fields", '{"op": "subscribe", "subscriptions": {"id": 1}}', None),
                             ("fields", '{"op": "unsubscribe", "subscriptionIds": "all"}', None)]))
    return st.one_of(common, own, own)


@st.composite
def _frames(draw: st.DrawFn, server: str) -> tuple[str, bytes, str | None]:
    """``(kind, bytes, runs)``: bad frames, fragments, huge messages (``runs``: as ``_messages``)."""
    kind, text, runs = draw(_messages(server))
    data = text.encode()
    how = draw(st.sampled_from(["message", "message", "message", "opcode", "rsv", "unmasked", "control",
                                "control_fragmented", "orphan", "interleaved", "utf8", "close_code", "too_big",
                                "fragments", "fragments_too_big", "binary", "ping_flood"]))
    if how == "message":
        return kind, frame(TEXT, data), runs
    if how == "fragments":
        cut = sorted(set(draw(st.lists(st.integers(0, len(data)), max_size=20))))
        pieces = [data[a:b] for a, b in zip([0, *cut], [*cut, len(data)], strict=True)]
        out = b"".join(frame(TEXT if i == 0 else 0, p, fin=i == len(pieces) - 1) for i, p in enumerate(pieces))
        return "fragmented " + kind, out, runs
    frames = {
        "opcode": lambda: frame(draw(st.sampled_from([3, 4, 5, 6, 7, 0xB, 0xC, 0xD, 0xE, 0xF])), data[:100]),
        "rsv": lambda: frame(TEXT, data[:100], rsv=draw(st.integers(1, 7))),
        "unmasked": lambda: frame(TEXT, data[:100], masked=False),
        "control": lambda: frame(PING, b"p" * draw(st.sampled_from([126, 1000, 70_000]))),
        "control_fragmented": lambda: frame(PING, b"p", fin=False),
        "orphan": lambda: frame(0, data[:100]),
        "interleaved": lambda: frame(TEXT, b"[1,", fin=False) + frame(TEXT, b"2]"),
        "utf8": lambda: frame(TEXT, draw(st.sampled_from([b"\xff\xfe", b"\xc3\x28", b"\xed\xa0\x80", b"a\x80"]))),
        "close_code": lambda: frame(CLOSE, draw(st.sampled_from([b"\x03", b"\x03\xe7", b"\x03\xed", b"\x13\x88",
                                                                 b"\x03\xe8\xff\xfe"]))),
        "too_big": lambda: frame(draw(st.sampled_from([TEXT, BINARY])), b"", length=draw(st.sampled_from(
            [MAX_MESSAGE + 1, 2**40, 2**63 - 1]))),
        "fragments_too_big": lambda: b"".join(frame(TEXT if i == 0 else 0, b"x" * 65_536, fin=False)
                                              for i in range(MAX_MESSAGE // 65_536 + 1)),
        "binary": lambda: frame(BINARY, draw(st.binary(max_size=64))),
        "ping_flood": lambda: frame(PING, b"x") * 2000,
    }
    return how, frames[how](), runs if how == "unmasked" else None  # (aiohttp takes an unmasked frame)


@st.composite
def inputs(draw: st.DrawFn) -> tuple[str, str, bytes, str | None]:
    """``(server, kind, bytes, runs)``."""
    server = draw(st.sampled_from(SERVERS))
    return (server, *draw(_frames(server)))


class WebSocketFamily:
    """The family's state: a connection per server, kept while the server keeps it."""

    name = FAMILY

    def __init__(self, fuzzer: Fuzzer, report: Report) -> None:
        self.fuzzer, self.report = fuzzer, report
        self.clients: dict[str, RawWs] = {}

    strategy = staticmethod(inputs)

    def __enter__(self) -> WebSocketFamily:
        return self

    def __exit__(self, *exc: object) -> None:
        for client in self.clients.values():
            client.close()

    def _client(self, server: str) -> RawWs:
        client = self.clients.get(server)
        if client is None or not client.open:
            if client is not None:
                client.close()
            client = self.clients[server] = RawWs(port(self.fuzzer.show, server), server)
        return client

    def send(self, item: tuple[str, str, bytes, str | None]) -> None:
        server, kind, data, runs = item
        self.fuzzer.tried[FAMILY][kind] += 1
        if runs is not None:  # (a stop or a behavior/list from a page: it may run)
            self._allow(runs)
        try:
            client = self._client(server)
        except (OSError, ConnectionError) as exc:
            self.report.check(False, f"websocket: cannot connect to the {server} server: {exc}")
            return
        self._outcome(server, client, client.send(data), f"{kind} {data[:120]!r}")

    def _allow(self, verb: str) -> None:
        self.fuzzer.oracle.sent(Input(FAMILY, VALID, "ws", "web", b"", signature(verb, {})))

    def _outcome(self, server: str, client: RawWs, sent: bool, what: str, timeout: float | None = None) -> None:
        """Probe ``client`` after an input: kept, or closed; a hang is a problem."""
        if sent and client.send(frame(TEXT, PROBE[server].encode())):
            outcome = client.until(lambda op, payload: op == TEXT and PROBED[server] in payload,
                                   **({"timeout": timeout} if timeout else {}))
        else:
            outcome = client.until(lambda op, payload: False, 1.0)  # (its close, if it said one)
            outcome.kind = "eof" if outcome.kind == "hung" else outcome.kind
        shown = {"answered": "kept", "closed": f"closed {outcome.code}"}.get(outcome.kind, outcome.kind)
        self.fuzzer.outcomes[FAMILY][f"{server} {shown}"] += 1
        self.report.check(outcome.kind != "hung", f"websocket: the {server} server neither answered nor closed "
                                                  f"after {what}")

    # -- scripted -----------------------------------------------------------------------

    def scripted(self) -> None:
        """At the three servers at once: a flood of valid and invalid messages and a subscribe or
        LISTEN flood on one connection, a client that never reads (then vanishes), and clients
        past the cap."""
        problems: list[str] = []
        threads = [threading.Thread(target=self._scripted, args=(server, problems)) for server in SERVERS]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
        for problem in problems:
            self.report.check(False, problem)

    def _scripted(self, server: str, problems: list[str]) -> None:
        address = port(self.fuzzer.show, server)
        try:
            silent = RawWs(address, server, rcvbuf=4096)
            self._subscribe_all(server, silent)
            flood = RawWs(address, server)
            valid, invalid = self._flood(server, flood)
            self.fuzzer.tried[FAMILY]["flood valid"] += len(valid)
            self.fuzzer.tried[FAMILY]["flood invalid"] += len(invalid)
            self._outcome(server, flood, flood.send(b"".join(frame(TEXT, m.encode()) for m in valid + invalid)),
                          "a flood", timeout=30.0)
            flood.close()
            self._past_the_cap(server, address, problems)
            time.sleep(max(0.0, NEVER_READ_S - 0.5))  # (the client that never reads: for a while)
            self.fuzzer.tried[FAMILY]["never reads"] += 1
            silent.sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            silent.close()  # (gone without a close: a reset)
        except (OSError, ConnectionError) as exc:
            problems.append(f"websocket: {server}: {type(exc).__name__}: {exc}")

    def _past_the_cap(self, server: str, address: int, problems: list[str]) -> None:
        """Clients until one is refused: within ``CLIENTS`` + 1, with a 503."""
        extra: list[RawWs] = []
        refused = ""
        try:
            while len(extra) <= CLIENTS and not refused:
                try:
                    extra.append(RawWs(address, server))
                except ConnectionError as exc:
                    refused = "503" if "503" in str(exc) else str(exc)
        finally:
            for client in extra:
                client.close()
        self.fuzzer.tried[FAMILY]["past the cap"] += 1
        self.fuzzer.outcomes[FAMILY][f"{server} past the cap {refused or 'accepted'}"] += 1
        if refused != "503":
            problems.append(f"websocket: the {server} server took {len(extra)} more clients, its cap {CLIENTS}: "
                            f"{refused or 'none refused'}")

    def _subscribe_all(self, server: str, client: RawWs) -> None:
        """Everything the server streams, to a client that will not read it."""
        if server == "oscquery":
            client.send(b"".join(frame(TEXT, json.dumps({"COMMAND": "LISTEN", "DATA": f"/pepper/joints/{j}"})
                                       .encode()) for j in JOINTS))
        elif server == "foxglove":
            ids = self._channels(client)
            client.send(frame(TEXT, json.dumps({"op": "subscribe", "subscriptions": [
                {"id": i, "channelId": c} for i, c in enumerate(ids)]}).encode()))

    def _channels(self, client: RawWs) -> list[int]:
        """The channel ids a Foxglove client is told of first (up to pepper/frame's advertisement)."""
        found: list[int] = []

        def take(op: int, payload: bytes) -> bool:
            if op == TEXT and payload.startswith(b'{"op": "advertise"'):
                channels = json.loads(payload)["channels"]
                found.extend(c["id"] for c in channels)
                return any(c["topic"] == "pepper/frame" for c in channels)
            return False
        client.until(take)
        return found

    def _flood(self, server: str, client: RawWs) -> tuple[list[str], list[str]]:
        """``FLOOD`` valid and ``FLOOD`` invalid messages (a subscribe or LISTEN flood among them)."""
        if server == "web":
            valid = [json.dumps({"type": "command", "id": i, "robot": "pepper", "verb": "behavior/list"})
                     for i in range(FLOOD // 8)]  # (each one runs on the robot: a few)
            for _ in valid:
                self._allow("behavior/list")
            invalid = [json.dumps({"type": "command", "id": i, "robot": "pepper", "verb": "dance"})
                       for i in range(FLOOD)]
        elif server == "oscquery":
            valid = [json.dumps({"COMMAND": c, "DATA": f"/pepper/joints/{JOINTS[i % len(JOINTS)]}"})
                     for i in range(FLOOD) for c in ("LISTEN", "IGNORE")]
            invalid = [json.dumps({"COMMAND": "LISTEN", "DATA": f"/made/up/{i}"}) for i in range(FLOOD)]  # past 64
        else:
            channel = self._channels(client)[0]
            valid = [json.dumps({"op": op, **({"subscriptions": [{"id": i, "channelId": channel}]}
                                              if op == "subscribe" else {"subscriptionIds": [i]})})
                     for i in range(FLOOD) for op in ("subscribe", "unsubscribe")]
            invalid = [json.dumps({"op": "subscribe", "subscriptions": [{"id": 10**6 + i, "channelId": channel}]})
                       for i in range(FLOOD)] + ['{"op": "unsubscribe", "subscriptionIds": [7]}'] * FLOOD
        return valid, invalid
