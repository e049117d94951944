"""Sending maps' robot commands (``targets.py``), and holding them when they must not go.

- **Capped.** Each map sends at most its target's ``hz`` commands a second, one at a
  time (the next waits for the robot's answer); a joint's newest angle replaces one
  that waits, and an angle equal to the last one sent is not sent again.
- **Validated like any command.** The owner checks each one; a refusal (a joint past
  its limits: ``out_of_range``) is counted and said in the log, and nothing moves.
- **Stopped means stopped.** Any ``stop`` of a robot (from a page, ``sonibus send``,
  OSC, another node: its owner says each command it ran on ``<robot>/events/command``)
  halts every map that drives it: nothing waiting is sent, nothing new is, until the
  operator resumes them (``resume`` on ``<node>/program/resume``). A command of a map
  that was on its way when the stop came is followed by a stop of the node's own, so
  it cannot carry on after the operator's.
- **A closed show sends none.** While ``<robot>/events/show`` says ``closed``, the maps
  that drive the robot send nothing (counted ``closed``); they send again when it opens.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any

import zenoh

from sonibus.bus import codec, keys, messages
from sonibus.bus.adapter import Adapter
from sonibus.bus.client import Outcome, ask
from sonibus.bus.commands import serving
from sonibus.bus.errors import CommandError

from .targets import Target

log = logging.getLogger(__name__)

TIMEOUT_S = 2.0                      # a command unanswered this long is given up (the next may go)
PROGRAM_VERBS = ("resume", "status")  # what <node>/program/<verb> takes


class Drive:
    """The robot commands of a map node's maps (``targets``: map → its target)."""

    counters = ("commands", "commands_refused", "halted", "closed", "stops_sent")

    def __init__(self, node: Adapter, targets: dict[str, Target]) -> None:
        self.node, self.bus, self.targets = node, node.bus, targets
        self.robots = sorted({t.robot for t in targets.values()})
        self.halted: dict[str, float] = {}    # robot → wall-clock time of the stop that halted its maps
        self.closed: set[str] = set()         # robots whose show says closed
        self._waiting: dict[str, dict[str, Any]] = {}  # map → its newest request, not sent yet
        self._last_sent: dict[str, float] = {}  # map → when its last command left (monotonic)
        self._angle: dict[str, float] = {}     # map → the last angle sent (joints/set)
        self._flying: dict[str, float] = {}    # map → when its unanswered command left (monotonic)
        self._stop_after: set[str] = set()     # maps whose command was on its way when a stop came
        self._checked: set[tuple[str, str]] = set()  # (map, robot) whose joint and limits were checked
        self._lock = threading.Lock()          # (stops, shows and resumes come on Zenoh's threads)
        self._gate = messages.Gate(self.bus.limits)
        for robot in self.robots:
            self._listen(robot)
        node.own(self.bus.serve(keys.program(node.name), self._serve))

    def _listen(self, robot: str) -> None:
        """Hear ``robot``'s stops and its show's state (its owner says them on its events)."""
        for kind in ("command", "show"):
            self.node.own(self.bus.on_sample(keys.event(robot, kind), self._event, f"{robot}'s {kind} events"))

    def set_target(self, name: str, target: Target | None) -> None:
        """Map ``name`` drives ``target`` from now on (None: nothing): a map added, removed or
        retargeted live. What waited for its old target is dropped; the caps are the new
        target's; a robot halted by a stop stays halted until resumed, whatever maps drive it."""
        with self._lock:
            targets = {n: t for n, t in self.targets.items() if n != name}
            if target is not None:
                targets[name] = target
            self.targets = targets  # (a new dict: the worker iterates the old one without the lock)
            for table in (self._waiting, self._angle, self._last_sent):
                table.pop(name, None)
            self._checked = {c for c in self._checked if c[0] != name}
            new = target is not None and target.robot not in self.robots
            if new:
                self.robots = sorted({*self.robots, target.robot})
        if new:
            self._listen(target.robot)

    # -- from the map node's worker ---------------------------------------------------

    def take(self, name: str, value: float | None, trigger: str | None) -> None:
        """Map ``name`` computed ``value`` (None: within its deadband) and its threshold's ``trigger``."""
        with self._lock:
            target = self.targets.get(name)
            if target is None:  # (retargeted to nothing, or removed, while this value was computed)
                return
            if target.triggered:
                request = target.request() if trigger == "on" else None
            else:
                request = target.request(value) if value is not None and value != self._angle.get(name) else None
            if request is None:
                return
            if target.robot in self.halted:
                self.node.count("halted")
                return
            if target.robot in self.closed:
                self.node.count("closed")
                return
            self._waiting[name] = request

    def flush(self) -> float:
        """Send what waits and may go now; the seconds until the next one may (1 s if none waits)."""
        now = time.monotonic()
        wait = 1.0
        sending = []
        with self._lock:
            for name, request in list(self._waiting.items()):
                target = self.targets[name]  # (set_target drops what waits for a target it takes away)
                flying = self._flying.get(name)
                if flying is not None and now - flying < TIMEOUT_S:
                    continue  # (its answer sends the next)
                due = self._last_sent.get(name, -1e9) + 1.0 / target.hz - now
                if due > 0:
                    wait = min(wait, due)
                    continue
                del self._waiting[name]
                self._last_sent[name] = self._flying[name] = now
                if target.command == "joints/set":
                    self._angle[name] = request["angles"][0]
                sending.append((name, target, request))
        for name, target, request in sending:
            ask(self.bus, target.robot, target.command, request,
                lambda outcome, name=name, target=target, request=request: self._answered(name, target, request,
                                                                                          outcome), TIMEOUT_S)
        return wait

    def learned(self, robot: str, joints: dict[str, tuple[float, float]]) -> None:
        """``robot``'s joints and their limits (from its info): a map whose joint it lacks, or
        whose ``to`` goes past the joint's limits, is said once (its owner would refuse it)."""
        for name, target in self.targets.items():
            chain = self.node.chains.get(name)
            if target.robot != robot or target.command != "joints/set" or (name, robot) in self._checked or not chain:
                continue
            self._checked.add((name, robot))
            limits = joints.get(target.joint)
            to = chain.spec.to
            if limits is None and joints:
                log.warning("%s: map '%s': %s has no joint '%s' — its joints: %s", self.node.name, name, robot,
                            target.joint, ", ".join(sorted(joints)))
            elif limits is not None and not limits[0] <= min(to) <= max(to) <= limits[1]:
                log.warning("%s: map '%s': to = [%g, %g] goes past %s's limits [%g, %g]: %s refuses the angles "
                            "past them (nothing moves) — give the map a to within them", self.node.name, name,
                            *to, target.joint, *limits, robot)

    @property
    def busy(self) -> bool:
        """Whether a command waits to be sent."""
        with self._lock:
            return bool(self._waiting)

    # -- answers, stops, shows --------------------------------------------------------

    def _answered(self, name: str, target: Target, request: dict[str, Any], outcome: Outcome) -> None:
        with self._lock:
            self._flying.pop(name, None)
            stop_after = name in self._stop_after and target.robot in self.halted
            self._stop_after.discard(name)
            if isinstance(outcome, CommandError):
                self._angle.pop(name, None)  # (sent again when the map computes it again)
        if isinstance(outcome, CommandError):
            self.node.warn(f"refused:{name}", f"map '{name}': {target.robot} refused {target.command} "
                                              f"{_args(request)}: {outcome.code}: {outcome.message} — nothing moved")
            self.node.count("commands_refused")  # (after the line: a test waiting on it finds it said)
        else:
            self.node.count("commands")
        if stop_after:
            self._stop(target.robot)

    def _stop(self, robot: str) -> None:
        """A stop of ours: a map's command left before the operator's stop was heard."""
        self.node.count("stops_sent")
        log.warning("%s: a map's command to %s was on its way when it was stopped: stopped it again",
                    self.node.name, robot)
        ask(self.bus, robot, "stop", {}, lambda outcome: None, TIMEOUT_S)

    def _event(self, key: str, payload: bytes | codec.Oversize) -> None:
        if not isinstance(payload, bytes):  # (over the gate's size: no event of ours)
            return
        try:
            event = self._gate.check(keys.Key.parse(key), payload)
        except ValueError:  # (the gate's refusal: a rogue's event moves nothing here)
            return
        robot = key.split("/")[0]
        if event.get("kind") == "command" and event.get("verb") == "stop":
            self.halt(robot)
        elif event.get("kind") == "show" and event.get("state") in ("open", "closed"):
            with self._lock:
                changed = (robot in self.closed) != (event["state"] == "closed")
                if event["state"] == "closed":
                    self.closed.add(robot)
                    self._drop(robot)
                else:
                    self.closed.discard(robot)
            if changed:
                log.info("%s: %s's show is %s: its maps %s", self.node.name, robot, event["state"],
                         "send nothing until it opens" if event["state"] == "closed" else "drive it again")

    def halt(self, robot: str) -> None:
        """``robot`` was stopped: its maps send nothing until resumed."""
        with self._lock:
            first = robot not in self.halted
            self.halted.setdefault(robot, time.time())
            self._drop(robot)
            self._stop_after.update(n for n in self._flying if n in self.targets and self.targets[n].robot == robot)
        if first:
            maps = ", ".join(n for n, t in self.targets.items() if t.robot == robot)
            log.warning("%s: %s was stopped: its maps (%s) move it no more until resumed — "
                        "sonibus resume %s%s", self.node.name, robot, maps, self.node.name,
                        f" {robot}" if len(self.robots) > 1 else "")

    def _drop(self, robot: str) -> None:
        """Forget what waits for ``robot`` (lock held)."""
        for name in [n for n in self._waiting if self.targets[n].robot == robot]:
            del self._waiting[name]
        for name in [n for n in self._angle if self.targets[n].robot == robot]:
            del self._angle[name]  # (the first angle after a resume or an opening goes, even if the same)

    def resume(self, robot: str = "") -> list[str]:
        """Let the maps drive ``robot`` again (all robots: ""); the robots resumed."""
        with self._lock:
            resumed = [r for r in self.halted if not robot or r == robot]
            for r in resumed:
                del self.halted[r]
        if resumed:
            log.info("%s: resumed: its maps drive %s again", self.node.name, ", ".join(resumed))
        return resumed

    def metrics(self) -> dict[str, Any]:
        """For the node's stats: the robots halted (wall-clock time of their stop), and closed."""
        with self._lock:
            return {"halted_robots": dict(self.halted), "closed_robots": dict.fromkeys(self.closed, 1)}

    def status(self) -> dict[str, Any]:
        with self._lock:
            return {"robots": list(self.robots), "halted": dict(self.halted), "closed": sorted(self.closed),
                    "maps": {n: t.describe() for n, t in self.targets.items()}}

    # -- <node>/program/<verb> ------------------------------------------------------------

    def _serve(self, query: zenoh.Query) -> None:
        verb = str(query.key_expr)[len(keys.program(self.node.name, "")):]
        serving.answer(query, verb, lambda: self._answer(verb, query))

    def _answer(self, verb: str, query: zenoh.Query) -> dict[str, Any]:
        if verb not in PROGRAM_VERBS:
            raise CommandError("unknown_verb", f"unknown request '{verb}' — a map node takes "
                                               f"{', '.join(PROGRAM_VERBS)}")
        args = serving.arguments(self._gate, query, verb)
        unknown = [k for k in args if k != "robot"] if verb == "resume" else list(args)
        robot = args.get("robot", "")
        if unknown or not isinstance(robot, str):
            takes = "robot = NAME (optional)" if verb == "resume" else "nothing"
            raise CommandError("bad_request", f"{verb}: takes {takes}, not {', '.join(unknown) or repr(robot)}")
        if robot and robot not in self.robots:
            raise CommandError("bad_request", f"resume: no map of node '{self.node.name}' drives '{robot}' — "
                                              f"its robots: {', '.join(self.robots)}")
        if verb == "status":
            return self.status()
        return {"resumed": self.resume(robot), **self.status()}


def _args(request: dict[str, Any]) -> str:
    return ", ".join(f"{k} = {v}" for k, v in request.items())
