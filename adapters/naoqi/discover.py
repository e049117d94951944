"""What the connected robot says it is: model, joints and their limits,
behaviors, postures, NAOqi version, and so where to read joints from.

Names come from ``ALMotion.getBodyNames("Body")`` and each joint's limits from
its own ``getLimits(name)`` call, so nothing depends on the order the robot
lists them in. Chains, units and posture targets come from the reference model
(``bus/robots.json``) for the joints it knows."""

from __future__ import annotations

import logging
import math
import re
from dataclasses import dataclass
from typing import Any

from sonibus.bus.robot import JointSpec, RobotModel, load_model, models

from .config import NaoqiConfig
from .connection import Link

log = logging.getLogger(__name__)

BODY_TYPES = {"pepper": "pepper", "juliette": "pepper", "nao": "nao"}
LIMIT_TOLERANCE = 1e-3  # rad: report getLimits that differ from robots.json by more


@dataclass(frozen=True)
class Robot:
    """One connected robot, as discovered."""

    model: RobotModel
    behaviors: tuple[str, ...]
    source: str                    # almemory | motion: where joint positions are read
    body_type: str = ""            # RobotConfig/Body/Type, e.g. "Pepper"
    name: str = ""                 # the robot's own name (ALSystem.robotName), e.g. "Juliette"
    version: str = ""              # NAOqi version, when the robot tells it
    cycle_ms: float | None = None  # DCM/CycleTime
    differences: tuple[str, ...] = ()  # limits that differ from the reference model

    @property
    def title(self) -> str:
        """Model and name, as a log line names the robot: ``Pepper 'Juliette'``."""
        model = self.body_type or self.model.name
        return f"{model} '{self.name}'" if self.name else model

    def info(self) -> dict[str, Any]:
        return {"body_type": self.body_type, "robot_name": self.name, "version": self.version,
                "cycle_ms": self.cycle_ms,
                "source": self.source, "limits_differ": list(self.differences)}


def discover(link: Link, config: NaoqiConfig) -> Robot:
    """Ask the robot; ``RemoteError``/``LinkDown`` when it cannot answer yet."""
    body_type = _memory(link, "RobotConfig/Body/Type") or _robot_config_type(link) or ""
    name = BODY_TYPES.get(str(body_type).lower(), str(body_type).lower() or config.model_name)
    reference = load_model(name) if name in models() else None
    model, differences = _model(link, name, reference)
    version = _version(link)
    base = str(_memory(link, "RobotConfig/Body/BaseVersion") or "")
    source = config.source if config.source != "auto" else choose_source(name, version, base)
    cycle = _memory(link, "DCM/CycleTime")
    behaviors = tuple(sorted(link.call("ALBehaviorManager", "getInstalledBehaviors")))
    robot_name = link.try_call("ALSystem", "robotName")
    return Robot(model, behaviors, source, str(body_type), str(robot_name or ""), version,
                 float(cycle) if isinstance(cycle, int | float) else None, tuple(differences))


def choose_source(model: str, version: str, base_version: str = "") -> str:
    """``motion`` where ALMemory mirrors joints only every 500 ms (NAO V6, NAOqi >= 2.8).

    >>> choose_source("pepper", "2.5.10.7"), choose_source("nao", "2.8.6.23"), choose_source("nao", "", "V6")
    ('almemory', 'motion', 'motion')
    """
    numbers = [int(n) for n in re.findall(r"\d+", version)[:2]]
    recent = len(numbers) == 2 and tuple(numbers) >= (2, 8)
    return "motion" if recent or (model == "nao" and base_version.upper().startswith("V6")) else "almemory"


def _model(link: Link, name: str, reference: RobotModel | None) -> tuple[RobotModel, list[str]]:
    names = [n for n in link.call("ALMotion", "getBodyNames", "Body") if not n.startswith("Wheel")]
    futures = {n: link.start("ALMotion", "getLimits", n) for n in names}  # one round trip for all
    joints, differences = {}, []
    for joint, future in futures.items():
        known = reference.joint(joint) if reference and reference.has_joint(joint) else None
        spec = _spec(joint, link.wait(future, f"ALMotion.getLimits({joint})"), known)
        if spec is None:
            log.warning("robot joint %s has no usable limits and no reference: not streamed", joint)
            continue
        joints[joint] = spec
        if known is not None and _differs(spec, known):
            differences.append(f"{joint} [{spec.min:.4f}, {spec.max:.4f}] vs robots.json "
                               f"[{known.min:.4f}, {known.max:.4f}]")
    order = [j for j in (reference.joint_names if reference else ()) if j in joints]
    order += [j for j in names if j not in order and j in joints]
    known_postures = reference.postures if reference else {}
    listed = link.try_call("ALRobotPosture", "getPostureList")
    postures = {p: dict(known_postures.get(p, {})) for p in (listed if listed is not None else known_postures)}
    return RobotModel(name, tuple(joints[j] for j in order), postures,
                      reference.description if reference else name), differences


def _spec(name: str, limits: Any, known: JointSpec | None) -> JointSpec | None:
    try:
        low, high, velocity = (float(v) for v in limits[0][:3])
    except (TypeError, ValueError, IndexError):
        return known
    if not all(math.isfinite(v) for v in (low, high, velocity)) or low >= high or velocity <= 0:
        return known
    unit = known.unit if known else ("fraction" if name.endswith("Hand") else "rad")
    return JointSpec(name, low, high, velocity, unit, known.chain if known else "")


def _differs(spec: JointSpec, known: JointSpec) -> bool:
    return abs(spec.min - known.min) > LIMIT_TOLERANCE or abs(spec.max - known.max) > LIMIT_TOLERANCE


def _memory(link: Link, key: str) -> Any:
    return link.try_call("ALMemory", "getData", key)


def _robot_config_type(link: Link) -> str | None:
    config = link.try_call("ALMotion", "getRobotConfig")  # [[keys], [values]]
    try:
        return str(dict(zip(config[0], config[1], strict=False))["Model Type"]).rstrip("0123456789HT")
    except (TypeError, KeyError, IndexError):
        return None


def _version(link: Link) -> str:
    for service, method in (("ALSystem", "systemVersion"), ("ALMemory", "version")):
        version = link.try_call(service, method)  # either may be missing on a robot (or a fake)
        if version:
            return str(version)
    return ""
