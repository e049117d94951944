"""The show's one worker: what the robot does, decided by the opening hours, the
motors' budget and the scenarios asked for — carried out with the robot's
commands only, one at a time, each bounded.

Outcomes, as docs/show.md states them:

- **Taking the robot** (at start, and whenever it comes back): ``stop`` (nothing
  it was doing goes on), then the state the hours say: open — stiffness on, the
  ready posture; closed — the rest posture, then stiffness off.
- **Opening, closing**: said at once on ``<robot>/events/show`` (and again every
  ``announce_every_s``), acted on when what runs has ended (an idle gesture, a
  scenario: neither is cut short by the clock).
- **Idle**: while open and nobody asks, the next idle behavior when the budget
  allows (``idle.Budget``); a scenario asked for during a gesture starts when it ends.
- **A scenario**: ``scenario`` ``started``, its steps in order, ``ended``. A step
  whose command is refused, whose end is not heard within its timeout, whose
  behavior fails or whose posture is interrupted aborts it (``aborted`` with the
  reason and the step), followed by a ``stop`` when something may still run
  (a behavior or a sentence whose end never came). A ``stop`` sent by anyone else
  (an operator) aborts it without another. Nothing is retried.
- **The robot lost** (its token gone, its owner saying it is not connected, a
  command unanswered): the scenario under way is aborted (``robot lost``) and
  nothing resumes half-way; the show waits for the robot, asking every second,
  and takes it again when it is back (above).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from sonibus.bus import keys
from sonibus.bus.adapter import Adapter
from sonibus.bus.errors import CommandError
from sonibus.bus.streams import Incoming

from .clock import ShowClock
from .config import Scenario, ShowConfig, Step
from .idle import Budget, Order
from .robot import Lost, Robot, Stopping, matching

log = logging.getLogger(__name__)

SLICE_S = 0.25  # a wait looks at the node's stopping, the robot and the requests at least this often
# After a behavior or a sentence ends, what else the robot says is waited for this long before the next step:
# an operator's stop ends a behavior with the behavior's own event, and its command event follows just after
SETTLE_S = 0.2


class StepFailed(Exception):
    """A step could not be done; ``stop``: something may still run on the robot."""

    def __init__(self, message: str, stop: bool = False) -> None:
        super().__init__(message)
        self.stop = stop


class Interrupted(StepFailed):
    """Someone else (an operator) stopped the robot: what the show was doing ends there."""

    def __init__(self) -> None:
        super().__init__("stopped by a stop command from elsewhere")


@dataclass(frozen=True)
class Request:
    """A scenario asked for, and by whom."""

    scenario: Scenario
    by: str = ""


class Director:
    """Runs the show for ``node`` (its counters, warnings and ``stopping``) on ``robot``."""

    def __init__(self, config: ShowConfig, clock: ShowClock, robot: Robot, node: Adapter) -> None:
        self.config, self.clock, self.robot, self.node = config, clock, robot, node
        idle = config.gestures
        self.budget = Budget(idle.rest_s, idle.max_per_hour)
        self.open: bool | None = None      # what the show does now (None: not decided yet)
        self.taken = False                 # the robot is in the state the hours say
        self.entered: bool | None = None   # the state the robot was last put in (open: awake; closed: resting)
        self.on_change: Callable[[str], None] | None = None  # told each change in a line (``sonibus rehearse``)
        self.running = ""                  # the scenario under way
        self.pending: Request | None = None
        self.interrupted = False           # a stop from someone else came during a scenario or gesture
        self._order: tuple[str, Order] | None = None  # the day it was drawn for, the idle order
        self._own_stops = 0                # stops sent by the show whose command event has not come yet
        self._announced = -float("inf")    # when the state was last said (monotonic)
        self._due: datetime | None = None  # the next change of the hours, as last said
        self._lock = threading.Lock()

    # -- requests (any thread) -----------------------------------------------------------

    def request(self, name: str, by: str = "") -> dict[str, Any]:
        """Take scenario ``name`` (run next, once what runs has ended); ``CommandError`` why not."""
        scenario = self.config.program.get(name)
        if scenario is None:
            raise CommandError("unknown_scenario", f"scenario: no scenario '{name}' — scenarios: "
                                                   f"{', '.join(self.config.program) or 'none'}")
        with self._lock:
            if not self.open:
                later = self.config.schedule.next_change(self.clock.now())
                raise CommandError("closed", f"scenario '{name}': the show is closed" +
                                   (f" — it opens {later:%a %H:%M}" if later else ""))
            if not self.robot.available:
                raise CommandError("unavailable", f"scenario '{name}': robot '{self.robot.name}' is not there "
                                                  f"({self.robot.why}); the show waits for it")
            busy = self.running or (self.pending.scenario.name if self.pending else "")
            if busy:
                raise CommandError("busy", f"scenario '{name}': scenario '{busy}' is under way — one at a time")
            self.pending = Request(scenario, by)
        self.robot.wake()
        return {"name": name, "state": "accepted"}

    def status(self) -> dict[str, Any]:
        now = self.clock.now()
        later = self.config.schedule.next_change(now)
        with self._lock:
            status = {"robot": self.robot.name, "open": bool(self.open), "available": self.robot.available,
                      "running": self.running, "pending": self.pending.scenario.name if self.pending else "",
                      "scenarios": list(self.config.program), "clock": now.isoformat(timespec="seconds"),
                      "next": later.isoformat(timespec="seconds") if later else None}
        if self.clock.rehearsal:
            status["rehearsal"] = self.clock.speed
        return status

    # -- the worker ------------------------------------------------------------------------

    def run(self) -> None:
        """Until the node stops."""
        self._schedule()
        while True:
            try:
                if not self.robot.available:
                    self._wait_back()
                    continue
                if not self.taken:
                    self.clock.begin()  # (a rehearsal's clock waits for the robot)
                    self._check_names()
                    self._quietly(lambda: self._send("stop"))  # (a stop refused in part: the rest goes on)
                    self._enter()
                    self.taken = True
                    self._announce(changed=False)  # (sinks started after the show missed its first word)
                self._tick()
            except Lost:
                self._lost()
            except Stopping:
                return

    def _check_names(self) -> None:
        """Say which behaviors and postures of the show the robot's info does not list (said, not refused:
        one may be installed later; its step fails meanwhile, saying so)."""
        cfg, info = self.config, self.robot.info
        wanted = {"behaviors": {*cfg.gestures.behaviors, *(s.behavior for c in cfg.program.values() for s in c.steps)},
                  "postures": {cfg.rest_posture, cfg.ready_posture,
                               *(s.posture for c in cfg.program.values() for s in c.steps)}}
        for kind, names in wanted.items():
            known = info.get(kind)
            missing = sorted(n for n in names - {""} if isinstance(known, list) and n not in known)
            if missing:
                listed = (f"its info lists {len(known)}: `sonibus send {self.robot.name} behavior/list`"
                          if kind == "behaviors" else f"its postures: {', '.join(map(str, known))}")
                self.node.warn(f"no {kind}", f"{kind} of the show not on robot '{self.robot.name}': "
                                             f"{', '.join(missing)} — {listed}")

    def _tick(self) -> None:
        if self._schedule() or self.entered != self.open:  # (a change said during a gesture is acted on now)
            self._enter()
            return
        with self._lock:
            request = self.pending
        if request is not None:
            self._scenario(request)
            return
        now = self.clock.seconds()
        wait = self._until_change(now)
        if self.open and self.config.gestures.behaviors:
            start = self.budget.next_at(now)
            if start <= now:
                self._gesture()
                return
            wait = min(wait, self.clock.real(start - now))
        self._wait(wait, woken=True)

    def _until_change(self, now: float) -> float:
        later = self.config.schedule.next_change(self.clock.now())
        if later is None:
            return SLICE_S * 4
        if not later.timestamp() > now:  # (waiting 0 s for it, again and again, would spin a core: issue 33)
            raise RuntimeError(f"the next change of the hours, {later.isoformat()}, is not after the show's "
                               f"clock ({datetime.fromtimestamp(now, self.clock.zone).isoformat()}): a bug")
        return self.clock.real(later.timestamp() - now)

    def _schedule(self) -> bool:
        """Whether the hours changed what the show does (said on ``<robot>/events/show``)."""
        now_open = self.config.schedule.is_open(self.clock.now())
        if now_open == self.open:
            return False
        with self._lock:
            self.open = now_open
            request = None if now_open else self.pending
            self.pending = self.pending if now_open else None
        self._announce(changed=True)
        if request is not None:  # (accepted just before closing, behind a gesture that ended after it)
            self._abort(request, 1, "the show closed before it started")
        return True

    def _enter(self) -> None:
        """Put the robot in the state of the hours: awake and ready, or resting with stiffness off."""
        cfg = self.config
        self.entered = self.open
        if self.open:
            self._quietly(lambda: self._send("stiffness", {"names": ["Body"], "value": 1.0}))
            self._quietly(lambda: self._posture(cfg.ready_posture, 0.0, cfg.step_timeout_s))
        else:
            self._quietly(lambda: self._posture(cfg.rest_posture, 0.0, cfg.step_timeout_s))
            self._quietly(lambda: self._send("stiffness", {"names": ["Body"], "value": 0.0}))

    def _quietly(self, step: Callable[[], object]) -> None:
        try:
            step()
        except StepFailed as exc:
            self.node.warn("enter", f"{'opening' if self.open else 'closing'} robot '{self.robot.name}': {exc}")

    def _lost(self) -> None:
        self.taken, self._own_stops, self.interrupted = False, 0, False
        with self._lock:
            request, self.pending = self.pending, None
        if request is not None:
            self._abort(request, 1, f"robot '{self.robot.name}' lost before it started ({self.robot.why})")

    def _wait_back(self) -> None:
        log.info("%s: waiting for robot '%s' (%s)", self.node.name, self.robot.name, self.robot.why)
        while not self.robot.available:
            if self.node.stopping.is_set():
                raise Stopping("the show stops")
            self._schedule()
            self._repeat()
            self.robot.probe()
            self._take(self.robot.next(SLICE_S))

    # -- idle --------------------------------------------------------------------------------

    def _gesture(self) -> None:
        today = self.clock.now().date().isoformat()
        if self._order is None or self._order[0] != today:  # drawn anew each day, from its date
            self._order = (today, Order(self.config.gestures.behaviors, self.config.gestures.order, today))
        name = self._order[1].next()
        self.node.count("gestures")
        self.interrupted = False
        self.budget.started(self.clock.seconds())
        try:
            self._behavior(name, self.config.gestures.timeout_s or self.config.step_timeout_s)
        except Interrupted:
            log.info("%s: idle gesture %s stopped from elsewhere", self.node.name, name)
        except StepFailed as exc:
            self.node.warn(f"idle {name}", f"idle gesture {name}: {exc}")
            if exc.stop:
                self._quietly(lambda: self._send("stop"))
        finally:
            self.budget.ended(self.clock.seconds())

    # -- scenarios ------------------------------------------------------------------------------

    def _scenario(self, request: Request) -> None:
        scenario, by = request.scenario, {"by": request.by} if request.by else {}
        with self._lock:
            self.pending, self.running = None, scenario.name
        self.interrupted = False
        self.node.count("scenarios")
        self._event("scenario", name=scenario.name, state="started", **by)
        log.info("%s: scenario %s started%s", self.node.name, scenario.name, f" by {request.by}" if by else "")
        index = 1  # the step under way (1: the first)
        try:
            for step in scenario.steps:
                self._step(step)
                index += 1
        except StepFailed as exc:
            self._abort(request, index, str(exc))
            if exc.stop:
                self._quietly(lambda: self._send("stop"))
            return
        except Lost:
            self._abort(request, index, f"robot '{self.robot.name}' lost ({self.robot.why})")
            raise
        except Stopping:
            self._abort(request, index, "the show stopped")
            raise
        finally:
            with self._lock:
                self.running = ""
        self._event("scenario", name=scenario.name, state="ended", **by)

    def _abort(self, request: Request, index: int, reason: str) -> None:
        self.node.count("aborted")
        log.warning("%s: scenario %s aborted at step %d: %s", self.node.name, request.scenario.name, index, reason)
        self._event("scenario", name=request.scenario.name, state="aborted", reason=reason, step=index,
                    **({"by": request.by} if request.by else {}))

    def _step(self, step: Step) -> None:
        if self.interrupted:
            raise Interrupted
        timeout = self.config.scenario_timeout(step)
        if step.behavior:
            self.budget.started(self.clock.seconds())
            try:
                self._behavior(step.behavior, timeout)
            finally:
                self.budget.ended(self.clock.seconds())
        elif step.say:
            self._send("say", {"text": step.say}, interruptible=True)
            if self._wait(timeout, matching("speech", text=step.say, state="done"), interruptible=True) is None:
                raise StepFailed(f"say {step.say[:40]!r}: not done within {timeout:g} s", stop=True)
            self._wait(SETTLE_S, interruptible=True)
        elif step.posture:
            self._posture(step.posture, step.speed, timeout, interruptible=True)
        else:
            self._wait(self.clock.real(step.pause_s), interruptible=True)

    # -- commands and their ends -------------------------------------------------------------------

    def _behavior(self, name: str, timeout: float) -> None:
        self._send("behavior/run", {"name": name}, interruptible=True)
        end = self._wait(timeout, matching("behavior", name=name, state=("stopped", "failed")), interruptible=True)
        if end is None:
            raise StepFailed(f"behavior {name}: no end heard within {timeout:g} s", stop=True)
        if end.event and end.event.get("state") == "failed":
            raise StepFailed(f"behavior {name} failed: {end.event.get('error', 'the robot says so')}")
        self._wait(SETTLE_S, interruptible=True)

    def _posture(self, name: str, speed: float, timeout: float, interruptible: bool = False) -> None:
        self._send("posture", {"name": name, **({"speed": speed} if speed else {})}, interruptible)
        end = self._wait(timeout, matching("posture", name=name, state=("reached", "interrupted")), interruptible)
        if end is None:
            raise StepFailed(f"posture {name}: not reached within {timeout:g} s", stop=True)
        if end.event and end.event.get("state") == "interrupted":
            raise StepFailed(f"posture {name} was interrupted")

    def _send(self, verb: str, args: dict[str, Any] | None = None, interruptible: bool = False) -> dict[str, Any]:
        """One command, answered; what came before it is no news of it (events already queued are taken first:
        with ``interruptible``, a stop from elsewhere among them ends what the show is doing, ``Interrupted``)."""
        while len(self.robot.queue):
            self._take(self.robot.next(0.0))
        if not self.robot.available:
            raise Lost(self.robot.why)
        if interruptible and self.interrupted:
            raise Interrupted
        self._own_stops += verb == "stop"
        try:
            return self.robot.command(verb, args)
        except CommandError as exc:
            self._own_stops -= verb == "stop"
            raise StepFailed(f"{verb} refused: {exc.message}") from None

    def _wait(self, seconds: float, match: Callable[[Incoming], bool] | None = None, interruptible: bool = False,
              woken: bool = False) -> Incoming | None:
        """The first event ``match`` accepts within ``seconds`` (real), else None; also None
        at once when ``woken`` and a scenario is asked for. ``Lost``, ``Stopping``, and with
        ``interruptible`` ``StepFailed`` when someone else's stop came."""
        deadline = time.monotonic() + seconds
        while True:
            if self.node.stopping.is_set():
                raise Stopping("the show stops")
            if not self.robot.available:
                raise Lost(self.robot.why)
            if interruptible and self.interrupted:
                raise Interrupted
            if woken and self.pending is not None:
                return None
            self._schedule()  # (said at its time; acted on when what runs has ended: ``_tick``)
            self._repeat()
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            event = self.robot.next(min(left, SLICE_S, self._until_due()))
            self._take(event)
            if event is not None and match is not None and match(event):
                return event

    def _take(self, event: Incoming | None) -> None:
        """Notice a stop the show did not send (an operator's): what runs must not go on."""
        if event is None or not matching("command", verb="stop", ok=True)(event):
            return
        if self._own_stops > 0:
            self._own_stops -= 1
            return
        log.info("%s: robot '%s' was stopped from elsewhere", self.node.name, self.robot.name)
        self.interrupted = True

    # -- what sinks hear ------------------------------------------------------------------------------

    def _until_due(self) -> float:
        """Real seconds until the next change of the hours (a wait ends then, to say it at its time)."""
        if self._due is None:
            return SLICE_S
        return max(0.0, self.clock.real(self._due.timestamp() - self.clock.seconds()))

    def _repeat(self) -> None:
        if time.monotonic() - self._announced >= self.config.announce_every_s:
            self._announce(changed=False)

    def _announce(self, changed: bool) -> None:
        now = self.clock.now()
        if changed and self._due is not None and self._due <= now:  # (the change's own instant, not the wait's end)
            now = self._due
        later = self.config.schedule.next_change(now)
        self._due = later
        fields: dict[str, Any] = {"state": "open" if self.open else "closed",
                                  "clock": now.isoformat(timespec="seconds"),
                                  "next": later.isoformat(timespec="seconds") if later else None}
        if self.clock.rehearsal:
            fields["rehearsal"] = self.clock.speed
        self._announced = time.monotonic()
        if changed:
            line = (f"the show is {fields['state']} ({now:%a %Y-%m-%d %H:%M:%S})"
                    + (f", {'closes' if self.open else 'opens'} {later:%a %H:%M}" if later else ""))
            log.info("%s: %s", self.node.name, line)
            if self.on_change is not None:
                self.on_change(f"{self.node.name}: {line}")
        self._event("show", **fields)

    def _event(self, kind: str, **fields: Any) -> None:
        try:
            self.node.bus.put(keys.event(self.robot.name, kind), {"t": time.time(), "kind": kind, **fields})
        except Exception as exc:  # a session closing under a stopping node: the log keeps the story
            if not self.node.stopping.is_set():
                raise
            log.debug("%s: %s event not sent: %s", self.node.name, kind, exc)
