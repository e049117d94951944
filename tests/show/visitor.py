"""A visitor at the kiosk, a sound patch sending OSC, and a witness of the robot's
events, in one process inside a test's network namespace (the test process is
outside it). It joins the bus as museum.toml says (a peer, multicast on) and
prints one JSON object per line: ``{"ready": true}`` once its session is open,
``{"key", "event"}`` for every event of the robot, and the answer to each line
read on stdin:

    press hello    the kiosk's button "hello", through the web node's kiosk protocol
    osc story      /<robot>/program/scenario "story" to the OSC gateway, over UDP (python-osc)
"""

from __future__ import annotations

import argparse
import asyncio
import json
import socket
import sys
import threading
import time
from typing import Any

import aiohttp
from pythonosc.osc_message import OscMessage
from pythonosc.osc_message_builder import OscMessageBuilder

from sonibus.bus import Bus, BusConfig, codec, open_session

WAIT_S = 10.0
_print_lock = threading.Lock()


def say(record: dict[str, Any]) -> None:
    with _print_lock:
        print(json.dumps(record), flush=True)


async def press(url: str, button: str) -> dict[str, Any]:
    """Press ``button`` on the kiosk at ``url`` (its WebSocket); the server's reply."""
    deadline = time.monotonic() + WAIT_S
    async with aiohttp.ClientSession() as http:
        while True:
            try:
                ws = await http.ws_connect(url)
                break
            except aiohttp.ClientError:  # (the web node may be starting)
                if time.monotonic() > deadline:
                    raise
                await asyncio.sleep(0.1)
        async with ws:
            await ws.send_json({"type": "press", "id": 1, "button": button})
            while True:
                message = await ws.receive_json(timeout=WAIT_S)
                if message.get("type") == "reply" and message.get("id") == 1:
                    return message


def osc(gateway: str, robot: str, scenario: str) -> list[Any]:
    """``/<robot>/program/scenario scenario`` to the gateway; its reply's address and arguments."""
    host, port = gateway.rsplit(":", 1)
    builder = OscMessageBuilder(address=f"/{robot}/program/scenario")
    builder.add_arg(scenario)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        sock.settimeout(WAIT_S)
        sock.sendto(builder.build().dgram, (host, int(port)))
        reply = OscMessage(sock.recv(65535))
    return [reply.address, *reply.params]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", default="pepper")
    parser.add_argument("--kiosk", required=True, help="the kiosk's WebSocket URL, token included")
    parser.add_argument("--gateway", required=True, help="host:port of the OSC gateway")
    args = parser.parse_args()
    session = open_session(BusConfig())
    try:
        bus = Bus(session, node="visitor")
        _, queue = bus.subscribe(f"{args.robot}/events/*", maxlen=100_000)

        def witness() -> None:
            while (item := queue.get()) is not None:
                say({"key": item[0], "event": codec.decode(item[1])})

        threading.Thread(target=witness, daemon=True).start()
        say({"ready": True})
        for line in sys.stdin:
            verb, _, arg = line.strip().partition(" ")
            try:
                if verb == "press":
                    say({"pressed": arg, "reply": asyncio.run(press(args.kiosk, arg))})
                elif verb == "osc":
                    say({"osc": arg, "reply": osc(args.gateway, args.robot, arg)})
            except Exception as exc:  # said, and the test fails on it
                say({"error": f"{line.strip()}: {type(exc).__name__}: {exc}"})
        queue.close()
    finally:
        session.close()


if __name__ == "__main__":
    main()
