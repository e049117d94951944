"""A libmapper program that is not sonibus, as webmapper or a Max patch would be: run
inside a test's network namespace (``python tests/libmapper/peer.py ...``).

``listen SOURCE EXPRESSION``: a device ``listener`` with an input ``yaw``, mapped (once,
by this program, as webmapper would) from ``SOURCE`` (``pepper/joints/HeadYaw``: a device
name without its ordinal) with ``EXPRESSION``; prints ``value <v>`` for each update.
``--no-map`` leaves the map to sonibus (after a restart of this program).

``send TARGET VALUE...``: a device ``sender`` with an output ``target`` mapped to ``TARGET``
(``pepper/cmd/joints/set/HipRoll``, ``y=x``), then each VALUE set in turn, 0.4 s apart;
prints ``sent <v>``. libmapper itself drops a NaN it is asked to send, so ``raw:nan``
is sent as a bare OSC message to TARGET's device and path, as a buggy or hostile peer
on the network can (libmapper takes signal updates from anyone who sends them).

``--unmap-after N``: release every map into ``yaw`` after N updates, from a graph of
its own (as a person unmapping in webmapper), printing ``unmapped``.

Both print ``ready <device name>`` and ``mapped`` and run until killed, ``--seconds`` or
SIGTERM (which frees the device: its peers see it leave, as when a synth is closed).
"""

from __future__ import annotations

import argparse
import signal
import sys
import time
from typing import Any

import libmapper as mpr
from pythonosc.udp_client import SimpleUDPClient


def find(graph: Any, device: Any, name: str, deadline: float) -> Any:
    """The signal ``<stable device>/<signal>`` of the graph, once it is there."""
    stable, _, signal = name.partition("/")
    while time.monotonic() < deadline:
        device.poll(20)
        for sig in graph.signals():
            owner = str(sig.device()[mpr.Property.NAME])
            if owner.rsplit(".", 1)[0] == stable and str(sig[mpr.Property.NAME]) == signal:
                return sig
    sys.exit(f"peer: no signal {name} on the network")


def raw(target: Any, value: float) -> None:
    """``value`` as a bare OSC message to ``target``'s device, at the signal's path."""
    owner = target.device()
    client = SimpleUDPClient(str(owner[mpr.Property.HOST]), int(owner[mpr.Property.PORT]))
    client.send_message("/" + str(target[mpr.Property.NAME]), value)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("mode", choices=("listen", "send"))
    parser.add_argument("endpoint")
    parser.add_argument("rest", nargs="*")
    parser.add_argument("--no-map", action="store_true")
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--unmap-after", type=float, default=0.0, help="release every map of the signal after "
                                                                       "this many updates came (0: never)")
    args = parser.parse_args()
    stopping: list[int] = []
    signal.signal(signal.SIGTERM, lambda *_: stopping.append(1))  # (ends the loop: the device says goodbye)
    graph, manager = mpr.Graph(), mpr.Graph()
    graph.set_interface("lo")
    manager.set_interface("lo")
    updates = [0]

    def updated(value: float) -> None:
        updates[0] += 1
        print(f"value {value!r}", flush=True)

    if args.mode == "listen":
        device = mpr.Device("listener", graph)
        sig = device.add_signal(mpr.Signal.Direction.INCOMING, "yaw", 1, mpr.Type.FLOAT, None, None, None, None,
                                lambda s, e, i, v, t: updated(v),
                                mpr.Object.Event.REMOTE_UPDATE)
    else:
        device = mpr.Device("sender", graph)
        sig = device.add_signal(mpr.Signal.Direction.OUTGOING, "target", 1, mpr.Type.FLOAT)
    while not device.get_is_ready():
        device.poll(20)
    print(f"ready {device[mpr.Property.NAME]}", flush=True)
    end = time.monotonic() + args.seconds
    if not args.no_map:
        other = find(graph, device, args.endpoint, time.monotonic() + 20)
        made = (mpr.Map("%y=" + args.rest[0].replace("x", "%x"), sig, other) if args.mode == "listen"
                else mpr.Map("%y=%x", other, sig))
        made.push()
        while not made.get_is_ready():
            device.poll(20)
        print("mapped", flush=True)
    values = list(args.rest) if args.mode == "send" else []
    while time.monotonic() < end and not stopping:
        device.poll(20)
        manager.poll(0)
        if args.unmap_after and updates[0] >= args.unmap_after:
            # as webmapper does: from a graph of its own, not the device's, once that graph knows the map
            # the device has (by its id: that graph may still know a map of a device of the same name
            # before this one, whose release removes nothing)
            running = {int(m[mpr.Property.ID]) for m in sig.maps()}
            into = [m for m in manager.maps() if m.get_is_ready() and int(m[mpr.Property.ID]) in running and any(
                str(s[mpr.Property.NAME]) == "yaw" for s in m.signals(mpr.Map.Location.DESTINATION))]
            for found in into:
                found.release()
            if into:
                args.unmap_after = 0.0
                print("unmapped", flush=True)
        if values:
            value = values.pop(0)
            if value.startswith("raw:"):
                raw(other, float(value[4:]))
            else:
                sig.set_value(float(value))
            print(f"sent {value}", flush=True)
            device.poll(400)
    device.free()
    manager.free()
    graph.free()


if __name__ == "__main__":
    main()
