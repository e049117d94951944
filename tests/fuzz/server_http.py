"""The ``http`` family: what a port scanner, a broken client or a hostile one sends the show's
three servers over HTTP. Generated (Hypothesis), one request per connection: malformed
request lines, bad methods, huge and too many headers, bad paths, OSCQuery's query strings.
Scripted after them, at the three servers at once: half-sent requests, a slowloris, silent
connections, and a burst of connections past the cap.

Each request must be answered (any status but a 5xx other than 503: a handler that raised) or
closed, within ``ANSWER_S``; each slow connection closed by the server's timeout; the
connections past the cap answered 503."""

from __future__ import annotations

import contextlib
import socket
import threading
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

from hypothesis import strategies as st

from .serving import ANSWER_S, CONNECTIONS, SERVERS, TIMEOUT_S, closed_within, cut_within, exchange, port

if TYPE_CHECKING:
    from .checks import Report
    from .fuzzer import Fuzzer

FAMILY = "http"
LINE_LIMIT = 8190       # aiohttp's max_line_size and max_field_size
HEADER_LIMIT = 64       # bus/web.py's MAX_HEADERS
PATHS = {
    "web": ["/", "/ws", "/kiosk", "/kiosk/ws", "/static/operator.js", "/static/style.css", "/kiosk/image/x"],
    "oscquery": ["/", "/pepper", "/pepper/joints", "/pepper/joints/HeadYaw", "/pepper/cmd/say",
                 "/pepper/cmd/joints/set", "/pepper/events/behavior", "/nobody/joints/x"],
    "foxglove": ["/", "/ws", "/foxglove"],
}
ATTRIBUTES = ["VALUE", "RANGE", "TYPE", "UNIT", "ACCESS", "DESCRIPTION", "CONTENTS", "FULL_PATH", "HOST_INFO",
              "TAGS", "CLIPMODE", "EXTENDED_TYPE", "CRITICAL", "OVERLOADS", "LISTEN", "value", "", "VALUE=1",
              "VALUE&RANGE", "%ZZ", "%00", "A" * 5000, "HOST_INFO&HOST_INFO", "VALUE;RANGE", "=", "&&&"]
JUNK = st.binary(min_size=1, max_size=64).map(lambda b: b.replace(b"\r\n", b"\n"))


@dataclass(frozen=True)
class Request:
    server: str
    kind: str
    data: bytes

    def describe(self) -> str:
        return f"{self.server} {self.kind} {self.data[:160]!r}" + (f"... ({len(self.data)} bytes)"
                                                                   if len(self.data) > 160 else "")


def _head(method: bytes, path: bytes, version: bytes = b"HTTP/1.1", headers: list[bytes] | None = None,
          host: bytes = b"127.0.0.1") -> bytes:
    lines = [method + b" " + path + b" " + version, b"Host: " + host, *(headers or [])]
    return b"\r\n".join(lines) + b"\r\n\r\n"


@st.composite
def requests(draw: st.DrawFn) -> Request:
    server = draw(st.sampled_from(SERVERS))
    kind = draw(st.sampled_from(["request_line", "method", "headers", "path", "query"]))
    path = draw(st.sampled_from(PATHS[server])).encode()
    if kind == "query":
        server = "oscquery"
        path = draw(st.sampled_from(PATHS["oscquery"] + ["/pepper/joints/HeadYaw/", "//pepper"])).encode()
        query = draw(st.lists(st.sampled_from(ATTRIBUTES), min_size=1, max_size=3))
        data = _head(b"GET", path + b"?" + "&".join(query).encode())
    elif kind == "request_line":
        data = draw(st.sampled_from([
            b"GET " + path + b"\r\n\r\n",                                   # HTTP/0.9
            b"GET  " + path + b"  HTTP/1.1\r\nHost: x\r\n\r\n",
            _head(b"GET", path, b"HTTP/9.9"), _head(b"GET", path, b"HTTP/1.1 extra"), _head(b"GET", path, b"HTTP/"),
            _head(b"GET", b"http://evil.example" + path), _head(b"GET", b"*"), _head(b"GET", b""),
            b"GET\t" + path + b"\tHTTP/1.1\r\n\r\n", _head(b"GET", path + b"\x00\x01\x7f"),
            _head(b"GET", b"/" + b"a" * (LINE_LIMIT + 10)),
            b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n",                               # an HTTP/2 client
            bytes.fromhex("160301002c010000280303") + b"\x00" * 40 + b"\r\n\r\n",  # a TLS ClientHello
        ])) if draw(st.booleans()) else draw(JUNK) + b"\r\n\r\n"
    elif kind == "method":
        method = draw(st.one_of(st.sampled_from([b"POST", b"PUT", b"DELETE", b"PATCH", b"TRACE", b"OPTIONS",
                                                 b"CONNECT", b"get", b"G\x00T", b"M" * 5000, b"HEAD", b"BREW"]),
                                st.binary(min_size=1, max_size=12).filter(lambda m: b" " not in m and b"\n" not in m)))
        body = draw(st.sampled_from([b"", b"x" * 10, b"{}"]))
        data = _head(method, path, headers=[b"Content-Length: %d" % len(body)]) + body
    elif kind == "headers":
        how = draw(st.sampled_from(["huge", "many", "no_colon", "space", "length", "chunked", "upgrade", "fold",
                                    "origin", "host"]))
        kind = f"headers {how}"
        headers = {
            "huge": [b"X-Big: " + b"b" * draw(st.sampled_from([LINE_LIMIT + 1, 20_000, 200_000]))],
            "many": [b"X-H%d: v" % i for i in range(draw(st.sampled_from([HEADER_LIMIT + 1, 200, 2000])))],
            "no_colon": [b"NoColonHere"],
            "space": [b"Content-Length : 5"],
            "length": [draw(st.sampled_from([b"Content-Length: -1", b"Content-Length: abc",
                                             b"Content-Length: 99999999999999999999",
                                             b"Content-Length: 1\r\nContent-Length: 2"]))],
            "chunked": [b"Transfer-Encoding: chunked"],
            "upgrade": [b"Upgrade: websocket", b"Connection: Upgrade",
                        draw(st.sampled_from([b"Sec-WebSocket-Version: 12", b"Sec-WebSocket-Key: notbase64!",
                                              b"Sec-WebSocket-Key: " + b"QQ==" * 100, b"Sec-WebSocket-Protocol: "
                                              + b"x," * 500]))],
            "fold": [b"X-Folded: a", b" continued"],
            "origin": [b"Origin: " + draw(st.sampled_from([b"http://evil.example", b"null", b"file://",
                                                           b"\xff\xfe", b"http://127.0.0.1:1"]))],
            "host": [],
        }[how]
        host = draw(st.sampled_from([b"evil.example", b"", b"[::1", b"a" * 300, b"127.0.0.1:99999"])) \
            if how == "host" else b"127.0.0.1"
        body = draw(st.sampled_from([b"5\r\nhello\r\n0\r\n\r\n", b"zz\r\n", b"ffffffffffffffff\r\n"])) \
            if how == "chunked" else b""
        data = _head(b"GET", path, headers=headers, host=host) + body
    else:
        data = _head(b"GET", draw(st.sampled_from([
            b"/static/../../../etc/passwd", b"/static/%2e%2e/%2e%2e/etc/passwd", b"/static/x%00.js", b"/%ff%fe",
            b"/static/" + b"a" * 200, b"//", b"/./.", b"/kiosk/image/../../x", b"/?" + b"x=1&" * 1000,
            b"/\xc3\x28", b"/pepper/" + b"j/" * 500, b"/#frag", b"/%", b"/static/.hidden"])))
    return Request(server, kind, data)


class HttpFamily:
    """The family as the campaign runs it (``strategy``, ``send`` each input, then ``scripted``)."""

    name = FAMILY
    strategy = staticmethod(requests)

    def __init__(self, fuzzer: Fuzzer, report: Report) -> None:
        self.fuzzer, self.report = fuzzer, report

    def __enter__(self) -> HttpFamily:
        return self

    def __exit__(self, *exc: object) -> None:
        pass  # (each request had a connection of its own)

    def send(self, request: Request) -> None:
        send(self.fuzzer, self.report, request)

    def scripted(self) -> None:
        scripted(self.fuzzer, self.report)


def send(fuzzer: Fuzzer, report: Report, request: Request) -> None:
    """One request on a new connection; its outcome counted, a 5xx (but 503) or a hang a problem."""
    fuzzer.tried[FAMILY][request.kind] += 1
    outcome = exchange(port(fuzzer.show, request.server), request.data)
    fuzzer.outcomes[FAMILY][f"{request.server} {outcome}"] += 1
    report.check(outcome == "hung" or not (outcome.startswith("5") and outcome != "503"),
                 f"http: the {request.server} server answered {outcome} to {request.describe()}")
    report.check(outcome != "hung", f"http: the {request.server} server neither answered nor closed within "
                                    f"{ANSWER_S:g} s: {request.describe()}")


HALF = b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n"  # never the blank line that ends the headers
# requests whose answers, pipelined and never read, fill the buffers (Foxglove answers HTTP with a few bytes)
UNREAD = {"web": b"GET /static/robot.js HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n" * 20_000,
          "oscquery": b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n" * 20_000}


def scripted(fuzzer: Fuzzer, report: Report) -> None:
    """At the three servers at once: two half-sent requests, a slowloris (a byte every 0.15 s),
    a silent connection, one that pipelines requests and never reads the answers, and the
    connections past the cap: each closed by the server's timeout (``TIMEOUT_S``), those past
    the cap answered 503 at once."""
    problems: list[str] = []

    def one_server(server: str) -> None:
        socks: list[tuple[str, socket.socket]] = []
        refused = 0
        address = ("127.0.0.1", port(fuzzer.show, server))
        try:
            for kind in ("half-sent", "half-sent", "slowloris", "silent"):
                sock = socket.create_connection(address, timeout=ANSWER_S)
                if kind == "half-sent":
                    sock.sendall(HALF)
                socks.append((kind, sock))
            if server in UNREAD:
                socks.append(("never reads", _never_reads(address, UNREAD[server])))
            burst = [socket.create_connection(address, timeout=ANSWER_S) for _ in range(CONNECTIONS + 8)]
            socks += [("past the cap", s) for s in burst]
            with contextlib.suppress(OSError):
                for s in burst:
                    s.sendall(HALF)
            slow = socks[2][1]
            deadline = time.monotonic() + TIMEOUT_S + ANSWER_S
            for byte in HALF:  # data that trickles in never pushes the timeout back
                try:
                    slow.sendall(bytes([byte]))
                except OSError:
                    break
                if closed_within(slow, time.monotonic() + 0.15)[0]:
                    break
            for kind, sock in socks:
                fuzzer.tried[FAMILY][kind] += 1
                shut, said = (cut_within(sock, deadline), b"") if kind == "never reads" else \
                    closed_within(sock, deadline)
                answer = " after 503" if said.startswith(b"HTTP/1.1 503") else ""
                fuzzer.outcomes[FAMILY][f"{server} {kind} {'closed' + answer if shut else 'left open'}"] += 1
                if not shut:
                    problems.append(f"http: the {server} server left a {kind} connection open "
                                    f"{TIMEOUT_S + ANSWER_S:g} s (its timeout is {TIMEOUT_S:g} s)")
                refused += bool(answer)
            if refused < len(socks) - CONNECTIONS:
                problems.append(f"http: the {server} server answered 503 to {refused} of {len(socks)} connections "
                                f"opened at once, its cap {CONNECTIONS}")
        except OSError as exc:
            problems.append(f"http: {server}: {type(exc).__name__}: {exc} (connecting {len(socks)} at once)")
        finally:
            for _, sock in socks:
                sock.close()

    threads = [threading.Thread(target=one_server, args=(server,)) for server in SERVERS]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    for problem in problems:
        report.check(False, problem)


def _never_reads(address: tuple[str, int], requests_: bytes) -> socket.socket:
    """A connection that sends what the server reads of ``requests_`` and reads nothing."""
    sock = socket.socket()
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.connect(address)
    sock.setblocking(False)
    with contextlib.suppress(BlockingIOError):
        sock.send(requests_)
    sock.setblocking(True)
    return sock
