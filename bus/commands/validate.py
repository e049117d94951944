"""Command requests validated against a robot's model, and the replies to them.

Structure (types, required fields, ranges that do not depend on the robot) comes
from the request schemas in ``schemas/v1/cmd/``; this module adds what the
schemas cannot say: finite numbers, known joints and their limits, known
behaviors and postures.

>>> from sonibus.bus.robot import load_model
>>> validate("joints/set", {"names": ["HeadYaw"], "angles": [0.3]}, load_model("pepper")).args
{'speed': 0.3, 'names': ['HeadYaw'], 'angles': [0.3]}
"""

from __future__ import annotations

import math
from collections.abc import Collection
from dataclasses import dataclass
from typing import Any

import jsonschema

from ... import schemas
from ..errors import CommandError
from ..keys import Key
from ..messages import BadMessage, Gate
from ..robot import RobotModel

_RANGE_CHECKS = {"minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum"}
LIMIT_TOLERANCE = 1e-5  # a limit as published (2.08567, 5 decimals) passes against the robot's float32 one


@dataclass(frozen=True)
class Command:
    """A validated request: ``verb`` and its arguments with defaults filled in."""

    verb: str
    args: dict[str, Any]


def verbs() -> tuple[str, ...]:
    return schemas.command_verbs()


def validate(verb: str, args: Any, model: RobotModel,
             behaviors: Collection[str] = ()) -> Command:
    """Check a request completely, or raise ``CommandError`` saying what is wrong."""
    if verb not in verbs():
        raise CommandError("unknown_verb", f"unknown command '{verb}' — known commands: {', '.join(verbs())}")
    if not isinstance(args, dict):
        raise CommandError("bad_request", f"{verb}: arguments must be a map, got {type(args).__name__}")
    _check_finite(verb, args)
    schema = schemas.command_schema(verb)
    error = jsonschema.exceptions.best_match(schemas.validator("cmd/" + verb).iter_errors(args))
    if error is not None:
        where = ".".join(str(p) for p in error.absolute_path) or "arguments"
        code = "out_of_range" if error.validator in _RANGE_CHECKS else "bad_request"
        message = error.message
        if error.validator in ("maxLength", "minLength"):
            message = f"is {len(error.instance)} characters long, must be {error.validator_value} " \
                      f"at {'most' if error.validator == 'maxLength' else 'least'}"
        raise CommandError(code, f"{verb}: {where}: {message}")
    filled = {k: p["default"] for k, p in schema["properties"].items() if "default" in p}
    filled.update(args)
    _check_against_model(verb, filled, model, behaviors)
    return Command(verb, filled)


def _check_finite(verb: str, value: Any, where: str = "arguments") -> None:
    if isinstance(value, float) and not math.isfinite(value):
        raise CommandError("bad_request", f"{verb}: {where}: {value} is not a finite number")
    if isinstance(value, dict):
        for key, item in value.items():
            _check_finite(verb, item, str(key))
    elif isinstance(value, list | tuple):
        for index, item in enumerate(value):
            _check_finite(verb, item, f"{where}.{index}")


def _known(kind: str, name: str, known: Collection[str], code: str) -> None:
    if name not in known:
        shown = ", ".join(sorted(known)[:12]) + (", ..." if len(known) > 12 else "")
        raise CommandError(code, f"unknown {kind} '{name}' — known: {shown or 'none'}")


def _check_against_model(verb: str, args: dict[str, Any], model: RobotModel,
                         behaviors: Collection[str]) -> None:
    if verb == "joints/set":
        names, angles = args["names"], args["angles"]
        if len(names) != len(angles):
            raise CommandError("bad_request", f"joints/set: {len(names)} names but {len(angles)} angles")
        if len(set(names)) != len(names):
            raise CommandError("bad_request", "joints/set: a joint is named twice")
        for name, angle in zip(names, angles, strict=True):
            _known("joint", name, model.joint_names, "unknown_joint")
            spec = model.joint(name)
            if not spec.min - LIMIT_TOLERANCE <= angle <= spec.max + LIMIT_TOLERANCE:
                raise CommandError("out_of_range", f"joints/set: {name} = {round(angle, 6)} is outside its limits "
                                   f"[{round(spec.min, 6)}, {round(spec.max, 6)}] {spec.unit}"
                                   + _degrees_hint(angle, spec.min, spec.max, spec.unit))
        args["angles"] = [model.joint(n).clamp(a) for n, a in zip(names, angles, strict=True)]
    elif verb == "stiffness":
        groups = {"Body", *(j.chain for j in model.joints), *model.joint_names}
        for name in args["names"]:
            _known("joint or chain", name, groups, "unknown_joint")
    elif verb == "posture":
        _known("posture", args["name"], model.postures, "unknown_posture")
    elif verb in ("behavior/run", "behavior/stop") and "name" in args:
        _known("behavior", args["name"], behaviors, "unknown_behavior")
    elif verb == "say" and not args["text"].strip():
        raise CommandError("bad_request", "say: text is blank")


def request_args(gate: Gate, key: str, payload: bytes, section: str, verb: str) -> dict[str, Any]:
    """The arguments of a request served by a node that is no robot's owner (a show's
    ``<robot>/program/<verb>``, a map node's ``<node>/maps/<verb>``): the gate's check, then
    the verb's schema in ``schemas/v1/<section>/``; ``CommandError("bad_request")`` in one
    line naming the argument (the gate's refusal: ``BadMessage``, a ``ValueError``, counted by
    the caller)."""
    try:
        args = gate.check(Key.parse(key), payload) if payload else {}
    except BadMessage as exc:
        raise CommandError("bad_request", f"{verb}: {exc}") from exc
    error = jsonschema.exceptions.best_match(schemas.validator(f"{section}/{verb}").iter_errors(args))
    if error is not None:
        where = ".".join(str(p) for p in error.absolute_path) or "arguments"
        raise CommandError("bad_request", f"{verb}: {where}: {error.message}")
    return args


def ok_reply(verb: str, result: dict[str, Any] | None = None) -> dict[str, Any]:
    return {"ok": True, "verb": verb, "result": result or {}}


def error_reply(verb: str, error: CommandError) -> dict[str, Any]:
    return {"ok": False, "verb": verb, "error": error.to_payload()}


def expand_stiffness_names(names: Collection[str], model: RobotModel) -> list[str]:
    """Joint names for a list of joints, chains and ``Body``."""
    out: list[str] = []
    for name in names:
        group = model.joint_names if name == "Body" else (model.chain(name) or (name,))
        out.extend(j for j in group if j not in out)
    return out


def _degrees_hint(value: float, low: float, high: float, unit: str) -> str:
    """What an angle refused in radians would be had it been meant in degrees, when it is
    past a turn (no angle in radians is) and that fits the limits (``45`` for HeadYaw:
    ``" (45° = 0.785398 rad: ...)"``); else nothing (3.0 was meant in radians).

    >>> _degrees_hint(45, -2.08567, 2.08567, "rad"), _degrees_hint(500, -2, 2, "rad"), _degrees_hint(3, -2, 2, "rad")
    (' (45° = 0.785398 rad: sonibus takes radians)', '', '')
    """
    if unit != "rad" or not math.isfinite(value) or abs(value) <= math.tau:
        return ""
    radians = math.radians(value)
    return f" ({value:g}° = {round(radians, 6):g} rad: sonibus takes radians)" if low <= radians <= high else ""
