"""Robots as libmapper devices: one ``Device`` per robot, named after it, on one
``Graph``; and a second ``Graph`` (``manager``) that sees every device, signal and
map of the network, as webmapper's does, and makes the maps sonibus restores: a map
made by its source device's own graph cannot be removed by webmapper (seen with
libmapper 2.6.1: the other side's release did nothing), one made by a graph of its
own can.

libmapper is not thread-safe: a ``Devices`` is made, used and closed on one thread
(the node's ``libmapper`` worker), which polls it often. Output signals are the
robot's joints (``joints/HeadYaw``, in its unit, with its limits) and derived values
(``derived/hand/RHand``); input signals (``cmd/joints/set/HeadYaw``) hand what a peer
sends to ``on_input``, which decides what reaches the robot: libmapper clamps nothing.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import libmapper as mpr

from .saved import Endpoint, stable

MAX_DEVICES = 64      # robots served as devices (names made up on the bus must not grow it)
MAX_SIGNALS = 512     # signals of one device (joints, derived values, inputs)
MAX_VECTOR = 64       # values of one derived signal
COMMAND = "cmd/joints/set/"  # input signals: a joint's target, as the OSC gateway's /<robot>/cmd/joints/set/<joint>

OnInput = Callable[[str, str, Any], None]   # (robot, joint, value as libmapper gave it)
OnMap = Callable[[Any, bool], None]         # (libmapper Map, whether it is there: False when removed)
OnLeft = Callable[[str], None]              # (the full name of a device that left the network)


@dataclass
class RobotDevice:
    """One robot's device and its signals by name."""

    robot: str
    device: Any
    outputs: dict[str, Any] = field(default_factory=dict)
    inputs: dict[str, Any] = field(default_factory=dict)

    @property
    def ready(self) -> bool:
        return bool(self.device.get_is_ready())

    @property
    def name(self) -> str:
        """Its name on the network, ``pepper.1`` (the ordinal is libmapper's choice, once ready)."""
        return str(self.device[mpr.Property.NAME])


class Devices:
    """The robots' devices on one graph; ``interface`` names the network ("": libmapper's choice)."""

    def __init__(self, interface: str, on_input: OnInput, on_map: OnMap, on_left: OnLeft,
                 commands: bool = True) -> None:
        self.graph, self.manager = mpr.Graph(), mpr.Graph()
        if interface:
            self.graph.set_interface(interface)
            self.manager.set_interface(interface)
        self.on_input, self.on_map, self.on_left, self.commands = on_input, on_map, on_left, commands
        self.robots: dict[str, RobotDevice] = {}
        self._events = self._graph_event  # (one bound method: the binding's callbacks are a module-wide set)
        # (the binding calls it for the events of both graphs: what it is told twice changes nothing)
        self.manager.add_callback(self._events, mpr.Type.MAP | mpr.Type.DEVICE)

    # -- devices and signals ------------------------------------------------------

    def set_robot(self, robot: str, info: Mapping[str, Any]) -> list[str]:
        """Serve ``robot`` as a device with the signals its info describes (new ones are
        added to a device already there); what could not be served, one line each.
        ``KeyError``/``TypeError``/``ValueError`` for an info not shaped as the schema says."""
        joints = [(str(j["name"]), str(j["unit"]), float(j["min"]), float(j["max"])) for j in info["joints"]]
        derived = [(str(d["name"]), int(d["size"]), str(d["unit"]), d.get("min"), d.get("max"))
                   for d in info.get("derived", ())]
        problems: list[str] = []
        served = self.robots.get(robot)
        if served is None:
            if len(self.robots) >= MAX_DEVICES:
                return [f"robot '{robot}' not served: already {MAX_DEVICES} devices"]
            served = self.robots[robot] = RobotDevice(robot, mpr.Device(robot, self.graph))
        for name, unit, low, high in joints:
            self._output(served, f"joints/{name}", 1, unit, low, high, problems)
            if self.commands:
                self._input(served, name, unit, low, high, problems)
        for name, size, unit, low, high in derived:
            if not 1 <= size <= MAX_VECTOR:
                problems.append(f"derived/{name}: size {size} is not in 1..{MAX_VECTOR}")
                continue
            bounds = (float(low), float(high)) if low is not None and high is not None else (None, None)
            self._output(served, f"derived/{name}", size, unit, *bounds, problems)
        return problems

    def _output(self, served: RobotDevice, name: str, size: int, unit: str, low: float | None,
                high: float | None, problems: list[str]) -> None:
        if name in served.outputs:
            return
        if len(served.outputs) + len(served.inputs) >= MAX_SIGNALS:
            problems.append(f"{name}: not served, {served.robot} already has {MAX_SIGNALS} signals")
            return
        served.outputs[name] = served.device.add_signal(
            mpr.Signal.Direction.OUTGOING, name, size, mpr.Type.FLOAT, unit,
            *((low, high) if size == 1 else ([low] * size, [high] * size) if low is not None else (None, None)))

    def _input(self, served: RobotDevice, joint: str, unit: str, low: float, high: float,
               problems: list[str]) -> None:
        if joint in served.inputs:
            return
        if len(served.outputs) + len(served.inputs) >= MAX_SIGNALS:
            problems.append(f"{COMMAND}{joint}: not served, {served.robot} already has {MAX_SIGNALS} signals")
            return
        robot = served.robot

        def updated(_signal: Any, _event: Any, _instance: Any, value: Any, _time: Any) -> None:
            self.on_input(robot, joint, value)

        # (the range tells webmapper where a new map starts; libmapper does not hold values to it)
        served.inputs[joint] = served.device.add_signal(
            mpr.Signal.Direction.INCOMING, COMMAND + joint, 1, mpr.Type.FLOAT, unit, low, high, None,
            updated, mpr.Object.Event.REMOTE_UPDATE)

    def drop_robot(self, robot: str) -> bool:
        """Take ``robot``'s device off the network (its peers see it leave); whether it was served."""
        served = self.robots.pop(robot, None)
        if served is None:
            return False
        served.device.free()
        return True

    def publish(self, robot: str, signal: str, values: Sequence[float]) -> bool:
        """Set output ``signal`` of ``robot`` (sent to its maps at the next poll); whether
        it is served. A value that is not finite is left out: no NaN leaves this node."""
        served = self.robots.get(robot)
        sig = served.outputs.get(signal) if served is not None else None
        if sig is None or not all(math.isfinite(v) for v in values):
            return False
        sig.set_value(float(values[0]) if len(values) == 1 else [float(v) for v in values])
        return True

    def poll(self) -> None:
        """Handle what came from the network (inputs, maps) and send what was set."""
        for served in list(self.robots.values()):
            served.device.poll(0)
        self.manager.poll(0)

    # -- the graph ------------------------------------------------------------------

    def ours(self, device_name: str) -> bool:
        """Whether a device of that name is one of ours (``pepper.1``)."""
        return any(s.name == device_name for s in self.robots.values())

    def _graph_event(self, kind: Any, found: Any, event: Any) -> None:
        # (the binding calls every callback for every graph of the process: one node of this kind per process)
        removed = bool(event & (mpr.Object.Event.REMOVED | mpr.Object.Event.EXPIRED))
        if kind == mpr.Type.DEVICE:
            if removed:
                self.on_left(str(found[mpr.Property.NAME]))
        else:
            self.on_map(found, not removed)

    def maps(self) -> Iterator[Any]:
        """Every map of the network (as the manager graph knows it)."""
        yield from self.manager.maps()

    def running(self) -> Iterator[Any]:
        """The maps our devices hold themselves (libmapper's local maps): what runs, as far as this
        end knows. (The manager graph keeps a map it was told of until told otherwise: a map
        unmapped from elsewhere stayed ACTIVE there.)"""
        for found in self.graph.maps():
            if found[mpr.Property.IS_LOCAL]:
                yield found

    def remote(self) -> Iterator[tuple[str, float]]:
        """Every device of the network (ours too, as the manager graph knows it): its name and when it
        was last heard from."""
        for device in self.manager.devices():
            synced = device[mpr.Property.SYNCED]
            yield str(device[mpr.Property.NAME]), synced.get_double() if synced is not None else 0.0

    def signal(self, device_name: str, signal: str) -> Any | None:
        """The signal ``signal`` of device ``device_name`` as the manager graph knows it (maps are
        made with these), or None."""
        for device in self.manager.devices():
            if str(device[mpr.Property.NAME]) == device_name:
                for sig in device.signals():
                    if str(sig[mpr.Property.NAME]) == signal:
                        return sig
        return None

    def close(self) -> None:
        """Every device off the network, the graph freed."""
        self.manager.remove_callback(self._events)
        for robot in list(self.robots):
            self.drop_robot(robot)
        self.manager.free()
        self.graph.free()


def endpoints(found: Any) -> tuple[list[Endpoint], Endpoint] | None:
    """A map's sources and destination as ``Endpoint``s (full device names), or None
    when the graph does not know them all yet."""
    try:
        sources = [_endpoint(s) for s in found.signals(mpr.Map.Location.SOURCE)]
        destinations = [_endpoint(s) for s in found.signals(mpr.Map.Location.DESTINATION)]
    except (AttributeError, TypeError):
        return None
    if not sources or len(destinations) != 1 or None in sources or destinations[0] is None:
        return None
    return sources, destinations[0]  # type: ignore[return-value]


def _endpoint(sig: Any) -> Endpoint | None:
    device = sig.device()
    if device is None:
        return None
    name = str(device[mpr.Property.NAME])
    return Endpoint(stable(name), str(sig[mpr.Property.NAME]), name)
