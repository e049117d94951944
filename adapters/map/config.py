"""Options of the ``map`` node: its maps, each a table of steps (the package's docstring
has an example; docs/mapping.md every step).

Every key of a map is checked here, so a file with a bad map is refused when it
is loaded, with its file, line and key (``bad("maps.cutoff.curve", ...)``: the
installation loader knows the line of each key of a map's table).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Any

from sonibus.bus import keys, messages
from sonibus.bus.errors import ConfigError, controls, visible
from sonibus.bus.options import bad

from .curves import CURVES, MAX_POINTS, Curve, Exp, Linear, Log, Points, S, default_base
from .expr import Expression
from .targets import Target, parse_target

MAX_MAPS = 256     # maps of one node
MAX_SOURCES = 64   # sources of one map (a hand's x, y, z and a few joints: tens at most)
SECTIONS = ("joints", "derived", "events")  # what a source may be
STEPS = ("source", "sources", "expr", "from", "calibrate_s", "to", "unit", "curve", "base", "points", "invert",
         "clip", "smooth_ms", "one_euro", "rate_limit", "deadband", "threshold", "enabled", "target")
ONE_EURO = ("min_cutoff", "beta", "d_cutoff")
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_AXIS = re.compile(r"^(.*/[^/.]+)\.([A-Za-z0-9_]+)$")


@dataclass(frozen=True)
class Source:
    """One source of a map: its name in the expression, the key (or pattern) it comes
    from, and which component of a derived value with several (``x``, ``2``; "" for all)."""

    name: str
    pattern: str
    axis: str = ""

    @property
    def section(self) -> str:
        return self.pattern.split("/")[1]


@dataclass(frozen=True, kw_only=True)
class MapSpec:
    """One map, checked: sources → (expression) → range → invert → curve → destination
    range → smoothing → rate limit → clip → deadband → threshold."""

    name: str
    sources: tuple[Source, ...]
    expr: Expression | None = None
    ranges: dict[str, tuple[float, float]] = field(default_factory=dict)  # `from`, by source name
    calibrate_s: float = 0.0
    to: tuple[float, float] = (0.0, 1.0)
    unit: str = ""
    curve: Curve = field(default_factory=Linear)
    invert: bool = False
    clip: tuple[float, float] | None = None
    smooth_ms: float = 0.0
    one_euro: tuple[float, float, float] | None = None   # min_cutoff Hz, beta, d_cutoff Hz
    rate_limit: float = 0.0
    deadband: float = 0.0
    threshold: tuple[float, float] | None = None          # on, off (off < on), in destination units
    enabled: bool = True
    target: Target | None = None                          # a robot command it drives (targets.py)

    @property
    def low(self) -> float:
        return min(self.to)

    @property
    def high(self) -> float:
        return max(self.to)


@dataclass(frozen=True, kw_only=True)
class MapConfig:
    """Options of the ``map`` adapter."""

    maps: dict[str, Any]          # name → its table of steps (see docs/mapping.md)
    silent_s: float = 1.0         # a map none of whose sources sent for this long says so (log, stats, event)
    unseen_s: float = 3.0         # a source that never sent within this long of the start is said in the log
    queue: int = 8192             # messages buffered before the oldest are dropped
    per_joint_keys: bool = False  # joints from <robot>/joints/* instead of <robot>/frame
    specs: tuple[MapSpec, ...] = field(init=False, default=())

    def __post_init__(self) -> None:
        if not self.maps:
            raise bad("maps", "is empty — give at least one [nodes.NAME.maps.MAP] table")
        if len(self.maps) > MAX_MAPS:
            raise bad("maps", f"{len(self.maps)} maps, at most {MAX_MAPS} in one node — split them over nodes")
        object.__setattr__(self, "specs", tuple(parse_map(name, table) for name, table in self.maps.items()))
        for key in ("silent_s", "unseen_s"):
            if not getattr(self, key) > 0:
                raise bad(key, f"{getattr(self, key):g} must be more than 0")
        if self.queue < 1:
            raise bad("queue", f"{self.queue} must be at least 1")

    @property
    def patterns(self) -> tuple[str, ...]:
        """Every source's key or pattern, once (a disabled map's too: an edit may enable it)."""
        return tuple(dict.fromkeys(s.pattern for spec in self.specs for s in spec.sources))


def parse_map(name: str, table: Any) -> MapSpec:
    """One map's table as a ``MapSpec``; ``ConfigError`` naming ``maps.<name>.<key>``."""
    where = f"maps.{name}"
    try:
        keys.check_name("map", name)
    except ValueError as exc:
        raise bad(where, str(exc)) from None
    if name == "map":  # (<node>/events/map: the node's own events, a map's silence)
        raise bad(where, "'map' is the name of the node's own events (<node>/events/map) — call this map another")
    if not isinstance(table, dict):
        raise bad(where, f"{table!r} is not a table — write [nodes.NODE.maps.{name}] with its steps")
    for key in table:
        if key not in STEPS:
            raise bad(f"{where}.{key}", f"unknown step '{key}' — steps: {', '.join(STEPS)}")
    sources = _sources(where, table)
    names = tuple(s.name for s in sources)
    expr = None
    if "expr" in table:
        text = _typed(where, table, "expr", str)
        try:
            expr = Expression(text, names)
        except ValueError as exc:
            raise bad(f"{where}.expr", str(exc)) from None
    elif len(sources) > 1:
        raise bad(f"{where}.expr", f"missing: how to combine {', '.join(names)}, e.g. expr = \"max({names[0]}, "
                                   f"{names[1]})\"")
    to = _pair(where, table, "to", (0.0, 1.0))
    if to[0] == to[1]:
        raise bad(f"{where}.to", f"[{to[0]:g}, {to[1]:g}] is no range: give two different values")
    spec: dict[str, Any] = {"name": name, "sources": sources, "expr": expr, "to": to,
                            "ranges": _from(where, table, names), "curve": _curve(where, table, to)}
    spec["unit"] = _typed(where, table, "unit", str, "")
    spec["invert"] = _typed(where, table, "invert", bool, False)
    spec["enabled"] = _typed(where, table, "enabled", bool, True)
    for key in ("calibrate_s", "smooth_ms", "rate_limit", "deadband"):
        value = _number(where, table, key, 0.0)
        if value < 0:
            raise bad(f"{where}.{key}", f"{value:g} must be 0 (off) or more")
        spec[key] = value
    if "clip" in table:
        low, high = _pair(where, table, "clip", (0.0, 0.0))
        if not min(to) <= low < high <= max(to):
            raise bad(f"{where}.clip", f"[{low:g}, {high:g}] must be an increasing window within to = "
                                       f"[{to[0]:g}, {to[1]:g}]")
        spec["clip"] = (low, high)
    if "one_euro" in table:
        spec["one_euro"] = _one_euro(where, table["one_euro"])
        if spec["smooth_ms"]:
            raise bad(f"{where}.one_euro", "and smooth_ms both smooth: keep one")
    if "threshold" in table:
        on, off = _pair(where, table, "threshold", (0.0, 0.0))
        if not off < on:
            raise bad(f"{where}.threshold", f"[{on:g}, {off:g}]: [on, off] with off below on (the hysteresis)")
        spec["threshold"] = (on, off)
    if "target" in table:
        spec["target"] = parse_target(where, table["target"], "threshold" in table)
    return MapSpec(**spec)


def _sources(where: str, table: dict[str, Any]) -> tuple[Source, ...]:
    if ("source" in table) == ("sources" in table):
        raise bad(f"{where}.source", "give source = \"KEY\" or sources = {a = \"KEY\", b = \"KEY\"} (one of them)")
    if "source" in table:
        found = {"x": _typed(where, table, "source", str)}
    else:
        found = table["sources"]
        if not isinstance(found, dict) or not found:
            raise bad(f"{where}.sources", f"{found!r} is not a table of sources such as {{a = \"pepper/joints/"
                                          "HeadYaw\"}")
        if len(found) > MAX_SOURCES:
            raise bad(f"{where}.sources", f"{len(found)} sources, at most {MAX_SOURCES} in one map")
    out = []
    for name, pattern in found.items():
        at = f"{where}.source" if "source" in table else f"{where}.sources"
        if not _NAME.match(name):
            raise bad(at, f"source name '{name}' must be a plain name (letters, digits, _), as in the expression")
        if not isinstance(pattern, str):
            raise bad(at, f"{pattern!r} is not a key such as \"pepper/joints/HeadYaw\"")
        match = _AXIS.match(pattern)
        key, axis = (match[1], match[2]) if match else (pattern, "")
        try:
            if any(c in key for c in " ?#@") or controls(key):
                raise ConfigError(f"'{visible(pattern)}' is not a key: it holds a space, '?', '#', '@' or a "
                                  "control character")
            keys.expr(key)
        except ConfigError as exc:
            raise bad(at, str(exc)) from None
        chunks = key.split("/")
        if len(chunks) < 3 or chunks[1] not in SECTIONS:
            raise bad(at, f"'{pattern}' is not a joint, derived value or event key — sources look like "
                          "pepper/joints/HeadYaw, pepper/derived/hand/R.z, pepper/events/motion")
        out.append(Source(name, key, axis))
    return tuple(out)


def _from(where: str, table: dict[str, Any], names: tuple[str, ...]) -> dict[str, tuple[float, float]]:
    value = table.get("from")
    if value is None:
        return {}
    if isinstance(value, dict):
        for name in value:
            if name not in names:
                raise bad(f"{where}.from", f"'{name}' is no source of this map — sources: {', '.join(names)}")
        spans = {name: _pair(where, value, name, (0.0, 0.0), f"from.{name}") for name in value}
    elif len(names) == 1:
        spans = {names[0]: _pair(where, table, "from", (0.0, 0.0))}
    else:
        raise bad(f"{where}.from", f"give each source its range: from = {{{names[0]} = [LOW, HIGH], ...}}")
    for name, (low, high) in spans.items():
        if low == high or not math.isfinite(high - low):
            raise bad(f"{where}.from", f"{name}: [{low:g}, {high:g}] is no range: give two different values")
    return spans


def _curve(where: str, table: dict[str, Any], to: tuple[float, float]) -> Curve:
    kind = _typed(where, table, "curve", str, "points" if "points" in table else "linear")
    if kind not in CURVES:
        raise bad(f"{where}.curve", f"'{kind}' is not a curve — curves: {', '.join(CURVES)}")
    if ("points" in table) != (kind == "points"):
        raise bad(f"{where}.points", "points = [[x, y], ...] goes with curve = \"points\" (and it needs them)")
    if "base" in table and kind not in ("exp", "log"):
        raise bad(f"{where}.base", f"is for curve = \"exp\" or \"log\", not '{kind}'")
    if kind in ("exp", "log"):
        base = _number(where, table, "base", default_base(to))
        if not base > 0 or base == 1:
            raise bad(f"{where}.base", f"{base:g} must be more than 0 and not 1")
        return Exp(base) if kind == "exp" else Log(base)
    if kind == "s":
        return S()
    if kind == "points":
        return Points(_points(where, table["points"]))
    return Linear()


def _points(where: str, points: Any) -> tuple[tuple[float, float], ...]:
    at = f"{where}.points"
    if not isinstance(points, list) or len(points) < 2:
        raise bad(at, "give at least two points [[x, y], ...], x and y fractions 0..1")
    if len(points) > MAX_POINTS:
        raise bad(at, f"{len(points)} points, at most {MAX_POINTS}")
    out: list[tuple[float, float]] = []
    for i, point in enumerate(points):
        if not (isinstance(point, list) and len(point) == 2 and all(_is_number(v) for v in point)):
            raise bad(at, f"point {i} {point!r} is not [x, y] (two numbers)")
        x, y = float(point[0]), float(point[1])
        if not (0 <= x <= 1 and 0 <= y <= 1):
            raise bad(at, f"point {i} [{x:g}, {y:g}]: x and y are fractions 0..1")
        if out and x <= out[-1][0]:
            raise bad(at, f"point {i} [{x:g}, {y:g}]: x must increase (the one before has x = {out[-1][0]:g})")
        out.append((x, y))
    return tuple(out)


def _one_euro(where: str, value: Any) -> tuple[float, float, float]:
    at = f"{where}.one_euro"
    if value is True:
        value = {}
    if not isinstance(value, dict):
        raise bad(at, f"{value!r} is not a table such as {{min_cutoff = 1.0, beta = 0.01}} (or true)")
    for key in value:
        if key not in ONE_EURO:
            raise bad(at, f"unknown key '{key}' — keys: {', '.join(ONE_EURO)}")
    got = {key: _number(where, value, key, default, f"one_euro.{key}")
           for key, default in (("min_cutoff", 1.0), ("beta", 0.0), ("d_cutoff", 1.0))}
    if not (got["min_cutoff"] > 0 and got["d_cutoff"] > 0 and got["beta"] >= 0):
        raise bad(at, "min_cutoff and d_cutoff (Hz) must be more than 0, beta 0 or more")
    return got["min_cutoff"], got["beta"], got["d_cutoff"]


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value) \
        and abs(value) <= messages.MAX_VALUE


def _number(where: str, table: dict[str, Any], key: str, default: float, shown: str = "") -> float:
    value = table.get(key, default)
    if not _is_number(value):
        raise bad(f"{where}.{shown or key}", f"{value!r} is not a number within ±{messages.MAX_VALUE:g}")
    return float(value)


def _pair(where: str, table: dict[str, Any], key: str, default: tuple[float, float],
          shown: str = "") -> tuple[float, float]:
    value = table.get(key, list(default))
    if not (isinstance(value, list | tuple) and len(value) == 2 and all(_is_number(v) for v in value)):
        raise bad(f"{where}.{shown or key}", f"{value!r} is not [LOW, HIGH] (two numbers within "
                                             f"±{messages.MAX_VALUE:g})")
    return float(value[0]), float(value[1])


def _typed(where: str, table: dict[str, Any], key: str, tp: type, default: Any = None) -> Any:
    value = table.get(key, default)
    if value is None or not isinstance(value, tp) or (tp is not bool and isinstance(value, bool)):
        raise bad(f"{where}.{key}", f"{value!r} is not {'a string' if tp is str else 'true or false'}")
    return value
