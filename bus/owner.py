"""``RobotAdapter``: the base of every adapter that owns a robot on the bus.

It owns the invariants every robot shares, whatever drives it (simulator,
NAOqi): one owner per robot, the robot's liveliness token, ``<robot>/info``,
the publishing of its frames and events, and the command path — every request validated
against the robot's model before the robot's verbs object sees it, one reply
each, and a ``command`` event for each executed command.

A subclass names the class that carries out its commands (``Verbs``, a
``verbs.RobotVerbs``: the registry checks it has every verb when it loads the
adapter), connects and sets ``self.model`` and ``self.verbs`` (an instance of
``Verbs``) in ``_open()``, and runs its frame loop in ``_acquire()`` (calling
``publish_frame`` per frame until ``self.stopping`` is set).

The robot's connection state (``bus/connection.py``) is the owner's too: it starts
as ``first_state`` ("connected", or "connecting" for an adapter that dials its robot
after ``_open``), a subclass says each change with ``self.connection.set(...)``,
and the owner serves it in the info, sends it as ``connection`` events and refuses
commands (but ``stop``) while the robot is not connected.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import OrderedDict
from collections.abc import Sequence
from typing import Any, ClassVar

import zenoh

from .. import schemas
from . import codec, commands, framing, keys, messages
from .adapter import Adapter
from .connection import UNREACHED, Connection
from .control import URGENT_REPLY
from .errors import CommandError
from .robot import RobotModel
from .verbs import RobotVerbs, bind

log = logging.getLogger(__name__)

STOP_IDS = 256  # the stops (by their id) an owner remembers having run: each runs once, whichever session has it first


class RobotAdapter(Adapter):
    """Owns one robot: publishes its frames and events, serves its commands."""

    Verbs: ClassVar[type[RobotVerbs]]
    """The class of ``self.verbs``; checked by the registry for every verb."""
    model: RobotModel
    verbs: RobotVerbs
    rate_hz: float = 100.0
    first_state: ClassVar[str] = "connected"
    """The robot's connection state once ``_open()`` returned: an adapter that reaches its robot
    later (NAOqi's) starts "connecting" and says each change (``self.connection.set``)."""
    stop_pending = False
    """True while a ``stop`` that did not reach the robot waits to be sent to it (an adapter that does so)."""

    @property
    def robot(self) -> str:
        return self.config.robot

    @classmethod
    def owned_robots(cls, config: Any) -> tuple[str, ...]:
        return (config.robot,)

    # -- lifecycle -------------------------------------------------------------

    def _start(self) -> None:
        self._claim()
        self.connection = Connection(lambda fields: self.publish_event("connection", **fields), self.first_state)
        self._open()
        self.connection.announce()  # from the first second: sinks know at once whether the robot is there
        declared = getattr(self, "Verbs", None)
        if declared is None or not isinstance(getattr(self, "verbs", None), declared):
            raise TypeError(f"{type(self).__name__}: _open() must set self.verbs to an instance of its Verbs class "
                            f"({getattr(declared, '__name__', 'none declared')})")
        self._run = bind(self.verbs)
        self._gate = messages.Gate(self.bus.limits)
        self.ownership.declare_publishers(self.model.joint_names)
        self.own(self.bus.serve(keys.info(self.robot), self._serve_info))
        self._stops: OrderedDict[str, None] = OrderedDict()
        self._stops_lock = threading.Lock()
        self.own(self.bus.serve(keys.command(self.robot), self._serve_command))
        # stop again, on the control session: no flood of data ahead of it (``bus/control.py``)
        urgent = self.bus.serve_urgent(keys.command(self.robot, "stop"),
                                       lambda query: self._serve_command(query, URGENT_REPLY))
        if urgent is not None:
            self.own(urgent)
        self.spawn(self._acquire, "acquire")
        if self.connection.answer_s is not None:
            self.spawn(self._watch_answers, "answers")

    def _watch_answers(self) -> None:
        """``not_answering`` once the robot gave no frame for ``answer_s``: woken when that may
        first be true (``Connection.due_in``), not ten times a second."""
        while not self.stopping.wait(self.connection.due_in(time.monotonic())):
            self.connection.check(time.monotonic())

    def _claim(self) -> None:
        self.ownership = self.claim_robot(self.robot)
        self.ownership.on_standby = self._stand_by

    def _stand_by(self) -> None:
        """Another owner keeps the robot from now: stop this one first (nobody may command it
        but with stop), on a worker of its own (a robot's stop may take a moment: not on Zenoh's thread)."""
        if getattr(self, "_run", None) is None:  # (not connected to the robot yet: nothing of it moves)
            return

        def stop() -> None:
            try:
                self._stop_robot()  # (a robot not reached: said in its result, and sent once it answers)
            except Exception as exc:  # said and counted; the node stands by all the same
                self.count("errors")
                self.warn("standby", f"robot '{self.robot}': its stop on going to stand by failed: "
                                     f"{type(exc).__name__}: {exc}")
        self.spawn(stop, "standby-stop")

    def _open(self) -> None:
        """Hook: connect to the robot and set ``self.model``, ``self.verbs`` (and ``self.rate_hz``)."""
        raise NotImplementedError

    def _acquire(self) -> None:
        """Hook: the frame loop; returns soon after ``self.stopping`` is set."""
        raise NotImplementedError

    # -- what a subclass calls --------------------------------------------------

    def publish_frame(self, t: float, seq: int, positions: Sequence[float], names: Sequence[str] | None = None,
                      extra: dict[str, Sequence[float]] | None = None) -> None:
        """One frame: ``positions`` in the order of ``names`` (default: the model's joints);
        ``extra`` adds quantities (``cmd``, ``cur``, ``temp``) in the same order.
        Published whole on ``<robot>/frame``, then per joint (while anyone listens there)."""
        names = names or self.model.joint_names
        # the usual frame (a simulator's, a robot's joints alone), its values checked in one go:
        # nothing to leave out (``valid_part``), and no map to make of it (``publish_values``)
        usual = extra is None and len(positions) == len(names) and messages.plain_floats(positions)
        message = None if usual else self._valid_frame(t, seq, positions, names, extra)
        now = time.monotonic()
        self.connection.answered(now)
        if (self.ownership.publish_values(t, seq, names, positions) if message is None
                else self.ownership.publish_frame(message)):  # (nothing while another owner keeps the robot)
            self.connection.published(now)
            self.stats.add("sent")
            self._stats_report.latencies.add(time.time() - t)  # acquisition to publish (``record_latency``)

    def _valid_frame(self, t: float, seq: int, positions: Sequence[float], names: Sequence[str],
                     extra: dict[str, Sequence[float]] | None) -> dict[str, Any]:
        """The frame of ``positions`` (and ``extra``) without the joints the gate would refuse,
        those left out counted and warned about; ``ValueError`` for columns of other lengths."""
        message = framing.frame(t, seq, names, positions, extra)
        if len(message["names"]) != len(message["v"]) or any(len(v) != len(message["names"])
                                                             for v in (extra or {}).values()):
            raise ValueError(f"{len(message['names'])} joint names but {len(positions)} positions (or extras)")
        message, left_out = framing.valid_part(message)
        if left_out:  # a glitching sensor: the other joints go on
            self.count("joints_left_out", len(left_out))
            self.warn("values", f"{self.robot}: {', '.join(left_out)} left out of frame {seq}: "
                                f"not a finite value within ±{messages.MAX_VALUE:g}")
        return message

    def publish_event(self, kind: str, **fields: Any) -> None:
        if not self.ownership.speaks:  # standing by for another owner: it speaks for the robot
            return
        self.bus.put(keys.event(self.robot, kind), {"t": time.time(), "kind": kind, **fields})

    def behaviors(self) -> Sequence[str]:
        """Names of the behaviors the robot can run (hook)."""
        return ()

    def connection_hint(self) -> str:
        """What to check when the robot is not connected (hook: "check it is on and reachable at ...")."""
        return ""

    def awareness_state(self) -> bool | None:
        """Whether the robot's basic awareness is on (it looks at people), as the owner knows it
        now, without asking the robot (the info is served on a Zenoh thread). None: the owner
        does not know, or the robot has none (ROS 2): the info then leaves ``awareness`` out (hook)."""
        return None

    def robot_info(self) -> dict[str, Any]:
        info: dict[str, Any] = {
            "robot": self.robot, "model": self.model.name,
            "joints": [j.to_info() for j in self.model.joints],
            "rate_hz": self.rate_hz, "behaviors": list(self.behaviors()),
            "postures": sorted(self.model.postures), "adapter": self.kind,
            "schema_version": schemas.VERSION,
            "owner": {"host": self.bus.host, "node": self.name},
            "connection": self.connection.info(standing_by=not self.ownership.active),
            "verbs": list(self.served_verbs()),
        }
        awareness = self.awareness_state()
        if awareness is not None:
            info["awareness"] = awareness
        return info

    def served_verbs(self) -> tuple[str, ...]:
        """The verbs this robot carries out (its info says them, so a page offers only those):
        every one, unless an adapter has no interface for some."""
        return tuple(commands.verbs())

    # -- serving ----------------------------------------------------------------

    def _serve_info(self, query: zenoh.Query) -> None:
        query.reply(keys.info(self.robot), codec.encode(self.robot_info()), encoding=codec.ENCODING)

    def _first_stop(self, stop_id: str | None, urgent: bool) -> bool:
        """Whether to run the stop ``stop_id`` (a query's ``id`` parameter) arriving on the
        control session (``urgent``) or the data session. An asker that names an id (every
        sonibus asker: ``client.ask``, ``client.stop_all``) reaches both sessions of this process,
        and the stop runs once, on the first it reaches; one that names none (a raw query) is
        run where every command is, on the data session only."""
        if not stop_id or len(stop_id) > 64:
            return not urgent
        with self._stops_lock:
            if stop_id in self._stops:
                return False
            self._stops[stop_id] = None
            if len(self._stops) > STOP_IDS:
                self._stops.popitem(last=False)
            return True

    def _serve_command(self, query: zenoh.Query, qos: dict[str, Any] | None = None) -> None:
        asked = str(query.key_expr)
        verb = keys.command_verb(asked)
        if verb == "stop" and not self._first_stop(query.parameters.get("id"), urgent=qos is not None):
            return  # answered on the other session (the asker takes the first answer)
        # a query for many robots (``*/cmd/stop``: ``client.stop_all``) is answered on this robot's own
        # key, so the asker knows who answered
        answer_on = keys.command(self.robot, verb) if verb and keys.is_concrete(verb) else asked
        args: Any = {}
        self.count("received")
        try:
            try:
                payload = query.payload.to_bytes() if query.payload is not None else b""
                args = self._gate.check(keys.Key.parse(answer_on), payload)
            except ValueError as exc:  # messages.BadMessage
                args = {}
                self.count("bad")
                if verb != "stop":  # stop must always work
                    raise CommandError("bad_request", f"{verb}: {exc}") from None
            self.ownership.check(verb, query.parameters.get("owner"))  # sent to another owner of the robot?
            reply = commands.ok_reply(verb, self.execute(verb, args))
        except CommandError as exc:
            reply = commands.error_reply(verb, exc)
        except Exception as exc:
            log.exception("%s: command %s failed", self.name, verb)
            reply = commands.error_reply(verb, CommandError("failed", f"{verb} failed: {exc}"))
        query.reply(answer_on, codec.encode(reply), encoding=codec.ENCODING, **(qos or {}))
        if verb in commands.verbs():
            event = {"verb": verb, "args": args if isinstance(args, dict) else {}, "ok": reply["ok"]}
            if not reply["ok"]:
                event["error"] = reply["error"]["message"]
            self.publish_event("command", **event)

    def execute(self, verb: str, args: Any) -> dict[str, Any]:
        """Validate and run one command; ``stop`` runs whatever its arguments and whatever
        the claims say. A node that stands by for another owner runs no other (``conflict``),
        nor does one whose robot is not connected (``not_connected``, ``not_answering``)."""
        self.ownership.check(verb)
        if verb == "stop":
            return self._stop_robot()
        command = commands.validate(verb, args, self.model, self.behaviors())
        refusal = self.connection.refusal(verb, self.robot, self.connection_hint())
        if refusal is not None:
            raise refusal
        return self._run[verb](**command.args)

    def _stop_robot(self) -> dict[str, Any]:
        """``stop`` is never refused for the robot's state, and never says it stopped a robot
        it did not reach: then its result says so (``reached`` false, the ``connection``
        state, the ``error``, and whether the owner sends it once the robot answers again,
        ``pending``)."""
        try:
            return self._run["stop"]()
        except CommandError as exc:
            if exc.code not in UNREACHED:
                raise
            return {"reached": False, "connection": self.connection.state, "error": exc.message,
                    "pending": self.stop_pending}
