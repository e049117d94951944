"""Options of the OSC sink: node-wide settings, and per-target overrides.

    [nodes.sound]
    adapter = "osc"
    subscribe = "pepper/joints/*"
    targets = ["127.0.0.1:3005",                          # node-wide settings
               {to = "127.0.0.1:57120", bundle = true, latency_ms = 50}]
    profile = "pepperosc"
"""

from __future__ import annotations

import string
from dataclasses import dataclass, fields
from typing import Any, Literal

from sonibus.bus import keys
from sonibus.bus.errors import ConfigError
from sonibus.bus.options import bad, from_mapping
from sonibus.bus.plan import without_audio

JOINT_FIELDS = ("robot", "section", "joint", "name", "key")
DERIVED_FIELDS = ("robot", "section", "feature", "name", "key")
EVENT_FIELDS = ("robot", "section", "kind", "name", "key")
EXTRAS = ("t", "seq")


def parse_target(target: str, lowest_port: int = 1) -> tuple[str, int]:
    """``"host:port"`` (``"[::1]:9001"`` for IPv6) → ``(host, port)``, or ``ConfigError``.
    ``lowest_port=0`` admits port 0 (any free port, for listening)."""
    host, sep, port = target.rpartition(":")
    if host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
    if not sep or not host or not port.isdigit() or not lowest_port <= int(port) <= 65535:
        raise ConfigError(f"target '{target}' is not host:port with a port in {lowest_port}..65535 "
                          f"(IPv6: \"[::1]:9001\")")
    return host, int(port)


def _check_template(key: str, template: str, allowed: tuple[str, ...]) -> None:
    if not template.startswith("/"):
        raise bad(key, f"'{template}' must start with '/'")
    try:
        used = {f for _, f, _, _ in string.Formatter().parse(template) if f is not None}
    except ValueError as exc:
        raise bad(key, f"'{template}' is not a template: {exc}") from None
    unknown = sorted(used - set(allowed))
    if unknown:
        raise bad(key, f"'{template}' uses unknown field '{{{unknown[0]}}}' — fields: "
                  + ", ".join("{" + f + "}" for f in allowed))


@dataclass(frozen=True, kw_only=True)
class TargetSettings:
    """What one receiver gets, and how."""

    profile: Literal["sonibus", "pepperosc"] = "sonibus"  # pepperosc: PepperOSC's wire format
    address: str = "/{robot}/joints/{joint}"              # joint samples
    derived_address: str = "/{robot}/derived/{feature}/{name}"
    event_address: str = "/{robot}/events/{kind}"
    values: Literal["raw", "normalized"] = "raw"          # normalized: 0..1 by the limits in <robot>/info
    extra: tuple[str, ...] = ()                           # more args after the value: "t" (float), "seq" (int)
    bundle: bool = False                                  # one bundle per frame, timetag = t + latency_ms
    latency_ms: float = 0.0
    max_rate_hz: float = 0.0                              # at most this many sends per key/frame (0: all)
    deadband: float = 0.0                                 # send a value only when it moved more than this
    on_change: bool = False                               # send a value only when it changed
    events: bool = True                                   # forward events

    def __post_init__(self) -> None:
        _check_template("address", self.address, JOINT_FIELDS)
        _check_template("derived_address", self.derived_address, DERIVED_FIELDS)
        _check_template("event_address", self.event_address, EVENT_FIELDS)
        for item in self.extra:
            if item not in EXTRAS:
                raise bad("extra", f"'{item}' is not one of {', '.join(EXTRAS)}")
        for key in ("latency_ms", "max_rate_hz", "deadband"):
            if not getattr(self, key) >= 0:
                raise bad(key, f"{getattr(self, key)} must be 0 or more")
        if self.profile == "pepperosc" and self.bundle:
            raise bad("bundle", "the pepperosc profile sends plain messages, as PepperOSC did; "
                      "use profile = \"sonibus\" for bundles")

    def settings(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(TargetSettings)}


@dataclass(frozen=True, kw_only=True)
class Target(TargetSettings):
    """One receiver: ``to = "host:port"`` plus its settings."""

    to: str

    def __post_init__(self) -> None:
        super().__post_init__()
        try:
            parse_target(self.to)
        except ConfigError as exc:
            raise bad("to", str(exc)) from None

    @property
    def framed(self) -> bool:
        """Whether this target is sent whole frames (bundles, PepperOSC's /latency)."""
        return self.bundle or self.profile == "pepperosc"


@dataclass(frozen=True, kw_only=True)
class OscSinkConfig(TargetSettings):
    """Options of the ``osc`` adapter; the target settings are defaults for every target."""

    subscribe: str | tuple[str, ...] = ("*/joints/*", "*/derived/**", "*/events/*")
    targets: tuple[str | dict[str, Any], ...] = ("127.0.0.1:9000",)
    max_age_ms: float = 100.0      # drop samples older than this (0: keep all)
    queue: int = 8192              # samples buffered before the oldest are dropped
    per_joint_keys: bool = False   # joints from <robot>/joints/* instead of <robot>/frame (bus/streams.py)

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "subscribe", without_audio(keys.patterns(self.subscribe), "an OSC sink"))
        if not self.targets:
            raise bad("targets", "targets is empty — give at least one host:port")
        if self.max_age_ms < 0 or self.queue < 1:
            raise bad("max_age_ms" if self.max_age_ms < 0 else "queue", "must be positive")
        object.__setattr__(self, "_targets", tuple(self._target(i, t) for i, t in enumerate(self.targets)))

    def resolved_targets(self) -> tuple[Target, ...]:
        """Every target with the node-wide settings filled in."""
        return self._targets  # type: ignore[attr-defined, no-any-return]

    def _target(self, index: int, spec: str | dict[str, Any]) -> Target:
        table = {"to": spec} if isinstance(spec, str) else spec
        try:
            return from_mapping(Target, {**self.settings(), **table}, f"targets[{index}]")
        except ConfigError as exc:
            raise bad("targets", str(exc)) from None
