"""A show program (adapter ``show``): opening hours, idle gestures with rests for the
motors, and scenarios started from a kiosk, OSC or MIDI — carried out on a robot
through its commands only, the ones a person would send, so a simulated robot and
a real Pepper play the same show.

    [nodes.show]
    adapter = "show"
    robot = "pepper"
    timezone = "Europe/Paris"
    hours = ["tue-sun 10:00-18:00"]

    [nodes.show.scenarios.hello]
    steps = [{say = "Hello!"}, {behavior = "animations/Stand/Gestures/Hey_1"}]

It says what it does on ``<robot>/events/show`` (``open``/``closed``) and
``<robot>/events/scenario`` (``started``/``ended``/``aborted``), and takes requests
on ``<robot>/program/<verb>`` (``scenario {name, by?}``, ``status``): the kiosk,
the OSC gateway and midi-in ask there (``client.ask_program``). docs/show.md has
every option and outcome; ``sonibus rehearse`` runs a day faster.

Modules: ``config`` (options), ``schedule`` (opening hours), ``idle`` (rests, the
cap, the order of idle behaviors), ``clock`` (the show's time, rehearsals),
``robot`` (the robot over the bus), ``director`` (the worker), ``cli``
(``sonibus rehearse``).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from datetime import datetime
from typing import Any

import zenoh

from sonibus import schemas
from sonibus.bus import keys, messages
from sonibus.bus.adapter import Adapter
from sonibus.bus.commands import serving
from sonibus.bus.errors import CommandError, OwnershipError

from .clock import ShowClock
from .config import ShowConfig
from .director import Director
from .robot import Robot

__all__ = ["Show", "ShowConfig"]

log = logging.getLogger(__name__)


class Show(Adapter):
    """A show program: opening hours, idle gestures with rests, scenarios from a kiosk, OSC or MIDI, by commands."""

    Config = ShowConfig
    counters = ("commands", "refused_commands", "gestures", "scenarios", "aborted", "requests", "requests_refused")

    def __init__(self, config: ShowConfig | None = None, *, name: str = "") -> None:
        super().__init__(config, name=name)
        self._rehearsal: tuple[float, datetime | None] | None = None
        self.on_change: Callable[[str], None] | None = None  # each opening and closing, in a line (rehearse prints it)

    def rehearse(self, speed: float, start: datetime | None = None) -> None:
        """Run the show's clock ``speed`` times faster, from ``start`` (default: now):
        ``sonibus rehearse``. Before ``start(bus)``."""
        if self.state != "new":
            raise RuntimeError(f"{self!r}: a rehearsal is set before the node starts")
        ShowClock(self.config.zone, speed, start)  # (ValueError now, not at start)
        self._rehearsal = (speed, start)

    def _start(self) -> None:
        cfg: ShowConfig = self.config
        speed, start = self._rehearsal or (1.0, None)
        self.clock = ShowClock(cfg.zone, speed, start, held=True)
        self._gate = messages.Gate(self.bus.limits)
        self._refuse_a_second_show()
        self.robot = Robot(self, cfg.robot, cfg.command_timeout_s)
        self.director = Director(cfg, self.clock, self.robot, self)
        self.director.on_change = self.on_change
        self.own(self.bus.serve(keys.program(cfg.robot), self._serve))
        self.address = f"scenarios ({', '.join(cfg.program) or 'none'}) on {keys.program(cfg.robot, 'scenario')}"
        idle = cfg.gestures
        log.info("%s: drives '%s': %s; %s; %s%s", self.name, cfg.robot, cfg.schedule.describe(),
                 f"{len(idle.behaviors)} idle behaviors ({idle.order}), at least {idle.rest_s:g} s apart, at most "
                 f"{idle.max_per_hour} an hour" if idle.behaviors else "no idle behaviors",
                 f"scenarios {', '.join(cfg.program)}" if cfg.program else "no scenarios",
                 f"; REHEARSAL: the clock runs {speed:g}× from {self.clock.now():%a %Y-%m-%d %H:%M}"
                 if self.clock.rehearsal else "")
        self.spawn(self.director.run, "show")

    def metrics(self) -> dict[str, Any]:
        if not hasattr(self, "director"):
            return {}
        status = self.director.status()
        return {"open": int(status["open"]), "available": int(status["available"]), "running": status["running"]}

    def _refuse_a_second_show(self) -> None:
        """One show drives a robot: ``OwnershipError`` naming the one that does already."""
        self.bus.discover()
        for answer in self.bus.query(keys.program(self.config.robot, "status"), {}, timeout=1.0):
            who = answer.get("result", {}) if answer.get("ok") else {}
            if who.get("node") and (who.get("host"), who.get("node")) != (self.bus.host, self.name):
                raise OwnershipError(f"robot '{self.config.robot}' already has a show: node '{who['node']}' on "
                                     f"'{who.get('host')}' — one show drives a robot: stop that node or give this "
                                     "one another robot")

    def _serve(self, query: zenoh.Query) -> None:
        verb = str(query.key_expr)[len(keys.program(self.config.robot, "")):]
        self.count("requests")
        serving.answer(query, verb, lambda: self._answer(verb, query), lambda: self.count("requests_refused"))

    def _answer(self, verb: str, query: zenoh.Query) -> dict[str, Any]:
        """The result of a request, checked like any command (the gate, then its schema)."""
        if verb not in schemas.program_verbs():
            raise CommandError("unknown_verb", f"unknown request '{verb}' — a show takes "
                                               f"{', '.join(schemas.program_verbs())}")
        args = serving.arguments(self._gate, query, verb, lambda: self.count("bad"), section="program")
        if verb == "status":
            return {**self.director.status(), "host": self.bus.host, "node": self.name}
        return self.director.request(args["name"], args.get("by", ""))
