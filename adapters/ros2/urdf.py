"""URDF, the robot description every ROS robot carries, parsed with the standard
library: its joints (type, limits, velocity, mimic) and the kinematic chain from
its root link to any link. Only what sonibus needs is read (no geometry, no
inertia); ``yourdfpy`` is the reference the tests compare against.

>>> urdf = parse('''<robot name="arm"><link name="base"/><link name="tool"/>
...   <joint name="j1" type="revolute"><parent link="base"/><child link="tool"/>
...     <axis xyz="0 0 1"/><limit lower="-1" upper="1" velocity="2" effort="5"/></joint></robot>''')
>>> urdf.name, urdf.root, [(j.name, j.lower, j.upper, j.velocity) for j in urdf.movable]
('arm', 'base', [('j1', -1.0, 1.0, 2.0)])
>>> [j.name for j in urdf.path("tool")]
['j1']
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

MOVABLE = ("revolute", "continuous", "prismatic")
TYPES = (*MOVABLE, "fixed", "floating", "planar")


class UrdfError(ValueError):
    """A URDF that cannot describe a robot: the message names the source and what is wrong."""


@dataclass(frozen=True)
class Mimic:
    """A joint that follows another: ``multiplier × joint + offset``."""

    joint: str
    multiplier: float = 1.0
    offset: float = 0.0


@dataclass(frozen=True)
class Joint:
    """One ``<joint>``: its origin in the parent link's frame, axis, limits (None: not given)."""

    name: str
    type: str
    parent: str
    child: str
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    axis: tuple[float, float, float] = (1.0, 0.0, 0.0)
    lower: float | None = None
    upper: float | None = None
    velocity: float | None = None
    mimic: Mimic | None = None

    @property
    def movable(self) -> bool:
        return self.type in MOVABLE


@dataclass(frozen=True)
class Urdf:
    """A parsed URDF: its joints in document order, and its root link."""

    name: str
    joints: tuple[Joint, ...]
    root: str
    source: str = "URDF"
    _index: dict[str, Joint] = field(default_factory=dict, compare=False, repr=False)

    @property
    def movable(self) -> tuple[Joint, ...]:
        return tuple(j for j in self.joints if j.movable)

    def joint(self, name: str) -> Joint:
        if len(self._index) != len(self.joints):
            self._index.update((j.name, j) for j in self.joints)
        return self._index[name]

    def path(self, tip: str, root: str = "") -> tuple[Joint, ...]:
        """The joints from link ``root`` (default: the URDF's root) down to link ``tip``."""
        root = root or self.root
        into = {j.child: j for j in self.joints}
        links = {j.child for j in self.joints} | {j.parent for j in self.joints}
        for link in (tip, root):
            if link not in links:
                raise UrdfError(f"{self.source}: no link '{link}' — links: {', '.join(sorted(links))}")
        out: list[Joint] = []
        link = tip
        while link != root:
            if link not in into or len(out) > len(self.joints):
                raise UrdfError(f"{self.source}: link '{tip}' does not hang below link '{root}'")
            out.append(into[link])
            link = into[link].parent
        return tuple(reversed(out))


def _floats(text: str | None, count: int, what: str, default: tuple[float, ...]) -> tuple[float, ...]:
    if text is None:
        return default
    try:
        values = tuple(float(v) for v in text.split())
    except ValueError:
        raise UrdfError(f"{what}: '{text}' is not {count} numbers") from None
    if len(values) != count or not all(math.isfinite(v) for v in values):
        raise UrdfError(f"{what}: '{text}' is not {count} finite numbers")
    return values


def _number(element: ET.Element | None, name: str, what: str) -> float | None:
    text = element.get(name) if element is not None else None
    if text is None:
        return None
    return _floats(text, 1, f"{what} {name}", ())[0]


def _joint(element: ET.Element, source: str) -> Joint:
    name, kind = element.get("name"), element.get("type")
    where = f"{source}: joint '{name}'"
    if not name:
        raise UrdfError(f"{source}: a <joint> without a name")
    if kind not in TYPES:
        raise UrdfError(f"{where}: type '{kind}' is not one of {', '.join(TYPES)}")
    parent, child = element.find("parent"), element.find("child")
    if parent is None or child is None or not parent.get("link") or not child.get("link"):
        raise UrdfError(f"{where}: needs <parent link=...> and <child link=...>")
    origin, axis, limit, mimic = (element.find(tag) for tag in ("origin", "axis", "limit", "mimic"))
    xyz = _floats(origin.get("xyz") if origin is not None else None, 3, f"{where} origin xyz", (0.0, 0.0, 0.0))
    rpy = _floats(origin.get("rpy") if origin is not None else None, 3, f"{where} origin rpy", (0.0, 0.0, 0.0))
    direction = _floats(axis.get("xyz") if axis is not None else None, 3, f"{where} axis", (1.0, 0.0, 0.0))
    norm = math.sqrt(sum(a * a for a in direction))
    if norm == 0.0 and kind in MOVABLE:
        raise UrdfError(f"{where}: axis is zero")
    lower, upper = _number(limit, "lower", where), _number(limit, "upper", where)
    velocity = _number(limit, "velocity", where)
    if kind in ("revolute", "prismatic"):
        if limit is None:
            raise UrdfError(f"{where}: a {kind} joint needs <limit lower upper velocity effort>")
        lower, upper = lower or 0.0, upper or 0.0  # URDF's defaults
        if lower > upper:
            raise UrdfError(f"{where}: limit lower {lower:g} above upper {upper:g}")
    follows = None
    if mimic is not None:
        if not mimic.get("joint"):
            raise UrdfError(f"{where}: <mimic> names no joint")
        multiplier = _number(mimic, "multiplier", where)
        follows = Mimic(str(mimic.get("joint")), 1.0 if multiplier is None else multiplier,
                        _number(mimic, "offset", where) or 0.0)
    return Joint(name, kind, str(parent.get("link")), str(child.get("link")), xyz, rpy,  # type: ignore[arg-type]
                 tuple(a / norm for a in direction) if norm else direction, lower, upper,  # type: ignore[arg-type]
                 velocity if velocity and velocity > 0 else None, follows)


def _line(text: str | bytes, name: str) -> int:
    """The line of ``text`` where joint ``name`` is declared (0 if not found): for errors only."""
    data = text.decode("utf-8", "replace") if isinstance(text, bytes) else text
    at = max(data.find(f'name="{name}"'), data.find(f"name='{name}'"))
    return data.count("\n", 0, at) + 1 if at >= 0 else 0


def parse(text: str | bytes, source: str = "URDF") -> Urdf:
    """The URDF in ``text``; ``UrdfError`` naming ``source`` (file:line) and the fault if it describes
    no robot. Linear in the number of joints; a kinematic loop (a link that is the child of two joints,
    or a chain that comes back to a link it passed) is refused, as it would make every walk down the
    tree endless."""
    try:
        robot = ET.fromstring(text)
    except ET.ParseError as exc:
        raise UrdfError(f"{source}: not XML ({exc})") from None
    if robot.tag != "robot":
        raise UrdfError(f"{source}: the root element is <{robot.tag}>, not <robot>")
    joints = tuple(_joint(element, source) for element in robot.findall("joint"))
    seen: set[str] = set()
    for joint in joints:
        if joint.name in seen:
            raise UrdfError(f"{source}:{_line(text, joint.name)}: joint '{joint.name}' is defined twice")
        seen.add(joint.name)
    links = [str(link.get("name")) for link in robot.findall("link")]
    known = set(links)
    into: dict[str, Joint] = {}
    for joint in joints:
        for link in (joint.parent, joint.child):
            if link not in known:
                raise UrdfError(f"{source}:{_line(text, joint.name)}: joint '{joint.name}' names link '{link}', "
                                "which has no <link>")
        if joint.mimic is not None and joint.mimic.joint not in seen:
            raise UrdfError(f"{source}:{_line(text, joint.name)}: joint '{joint.name}' mimics "
                            f"'{joint.mimic.joint}', which is no joint")
        if joint.child in into:
            raise UrdfError(f"{source}:{_line(text, joint.name)}: link '{joint.child}' is the child of joint "
                            f"'{into[joint.child].name}' and of joint '{joint.name}': a loop (a URDF is a tree)")
        into[joint.child] = joint
    _no_cycle(into, source, text)
    roots = [link for link in links if link not in into]
    if len(roots) != 1:
        raise UrdfError(f"{source}: {len(roots)} root links ({', '.join(roots[:10]) or 'a cycle'}); a URDF has one")
    return Urdf(str(robot.get("name") or "robot"), joints, roots[0], source)


def _no_cycle(into: dict[str, Joint], source: str, text: str | bytes) -> None:
    """Refuse a chain that comes back to a link it passed (each link has at most one parent here):
    every link is walked up once, so this is linear."""
    state: dict[str, int] = {}  # 1: on the walk being made, 2: known to reach a root
    for start in into:
        walk: list[str] = []
        link = start
        while link in into and state.get(link) is None:
            state[link] = 1
            walk.append(link)
            link = into[link].parent
        if state.get(link) == 1:
            joint = into[link]
            raise UrdfError(f"{source}:{_line(text, joint.name)}: joint '{joint.name}' closes a loop: link "
                            f"'{link}' hangs below itself (a URDF is a tree)")
        for passed in walk:
            state[passed] = 2


def group_states(text: str | bytes, source: str = "SRDF") -> dict[str, dict[str, float]]:
    """The named states of an SRDF (MoveIt's semantic description): ``<group_state name>``
    with its ``<joint name value>``s, as postures. Two groups' states of one name are merged.

    >>> group_states('<robot name="a"><group_state name="home" group="arm"><joint name="j1" value="0.5"/>'
    ...              '</group_state></robot>')
    {'home': {'j1': 0.5}}
    """
    try:
        robot = ET.fromstring(text)
    except ET.ParseError as exc:
        raise UrdfError(f"{source}: not XML ({exc})") from None
    out: dict[str, dict[str, float]] = {}
    for state in robot.findall("group_state"):
        name = state.get("name")
        if not name:
            raise UrdfError(f"{source}: a <group_state> without a name")
        for joint in state.findall("joint"):
            value = _floats(joint.get("value"), 1, f"{source}: group_state '{name}' joint '{joint.get('name')}'", ())
            out.setdefault(name, {})[str(joint.get("name"))] = value[0]
    return out
