"""Options of the ``web`` adapter (docs/web.md).

    [nodes.web]
    adapter = "web"
    listen = "127.0.0.1:8080"     # port 0: any free port
    token = ""                    # operator token: required to listen beyond this machine
    kiosk_token = ""              # the kiosk's token: /kiosk and /kiosk/ws only

    [nodes.web.kiosk]
    robot = "pepper"

    [[nodes.web.kiosk.buttons]]
    id = "wave"
    label = "Say hello"
    image = "images/wave.png"     # optional, served at /kiosk/image/<id>
    behavior = "wave"             # or: say = "Hello, visitors!", or: scenario = "hello" (a show's, docs/show.md)
"""

from __future__ import annotations

import ipaddress
import re
import socket
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sonibus.adapters.osc.gateway import parse_endpoint
from sonibus.bus import keys
from sonibus.bus.errors import ConfigError
from sonibus.bus.options import bad, from_mapping
from sonibus.bus.web import Limits

MAX_SAY = 500  # characters of a say button's text (the say verb's bound)
_BUTTON_ID = re.compile(r"[A-Za-z0-9_-]{1,64}")


@dataclass(frozen=True)
class Button:
    """One kiosk button: a behavior to run, a text to say, or a scenario of the robot's show."""

    id: str                # [A-Za-z0-9_-], unique: what the page sends in "press"
    label: str
    image: str = ""        # a file, served at /kiosk/image/<id>
    behavior: str = ""     # exactly one of behavior, say and scenario
    say: str = ""
    scenario: str = ""     # asked of the show that drives the robot (<robot>/program/scenario)
    timeout_s: float = 120.0  # no end heard from the robot by then: the button fails and the kiosk is free again

    def __post_init__(self) -> None:
        if not _BUTTON_ID.fullmatch(self.id):
            raise bad("id", f"{self.id!r} must be 1..64 letters, digits, '_' or '-'")
        if not self.label.strip():
            raise bad("label", "must not be blank: it is what the visitor reads")
        if sum(map(bool, (self.behavior, self.say, self.scenario))) != 1:
            raise bad("behavior", f"button {self.id!r} needs exactly one of 'behavior' (a behavior to run), "
                                  "'say' (a text to say) and 'scenario' (a scenario of the robot's show)")
        if not 0 < self.timeout_s <= 3600:
            raise bad("timeout_s", f"button {self.id!r}: {self.timeout_s:g} must be in (0, 3600] seconds "
                                   "(longer than the scenario takes: a button without an end frees the kiosk then)")
        if self.say and (not self.say.strip() or len(self.say) > MAX_SAY):
            raise bad("say", f"button {self.id!r}: the text must be 1..{MAX_SAY} characters, not blank")
        # (a relative path is the installation file's folder's: checked when the node starts, ``WebPages``)
        if self.image and Path(self.image).expanduser().is_absolute() and not Path(self.image).expanduser().is_file():
            raise bad("image", f"button {self.id!r}: {self.image!r} is not a file — give an image file or "
                               "leave 'image' out")

    @property
    def kind(self) -> str:
        return "behavior" if self.behavior else "say" if self.say else "scenario"

    @property
    def command(self) -> tuple[str, dict[str, Any]]:
        """The verb and arguments a press sends to the kiosk's robot (a scenario: to its show)."""
        if self.scenario:
            return "scenario", {"name": self.scenario, "by": "kiosk"}
        return ("behavior/run", {"name": self.behavior}) if self.behavior else ("say", {"text": self.say})


@dataclass(frozen=True)
class Kiosk:
    """The kiosk: its robot and its buttons."""

    robot: str = ""
    buttons: tuple[Button, ...] = ()


@dataclass(frozen=True)
class WebConfig:
    """Options of the ``web`` adapter."""

    listen: str = "127.0.0.1:8080"   # host:port of HTTP and WebSocket
    robots: tuple[str, ...] = ("*",)  # robots shown to the operator (key globs of robot names)
    token: str = ""                  # operator token (?token= or Authorization: Bearer); needed off loopback
    kiosk_token: str = ""            # the kiosk's token: /kiosk routes only
    update_hz: float = 25.0          # frames pushed per robot per second (latest only)
    slider_hz: float = 20.0          # joint commands per joint per second at most (latest wins)
    speed: float = 0.2               # fraction of max speed of a joints/set that names none
    timeout: float = 5.0             # seconds a robot has to answer a command
    queue: int = 4096                # messages from the bus waiting; past this the oldest are dropped
    limits: Limits = field(default_factory=Limits)  # [nodes.<name>.limits]: connections, clients (pages), timeout_s
    kiosk: dict[str, Any] = field(default_factory=dict)  # [nodes.<name>.kiosk]: robot, [[...buttons]]
    host: str = field(init=False, repr=False, compare=False)
    port: int = field(init=False, repr=False, compare=False)
    stand: Kiosk = field(init=False, repr=False, compare=False)  # ``kiosk`` checked

    def __post_init__(self) -> None:
        host, port = parse_endpoint("listen", self.listen)
        object.__setattr__(self, "host", host)
        object.__setattr__(self, "port", port)
        if not self.token and not loopback(host):
            raise bad("listen", f"{self.listen!r} serves beyond this machine without a token — set token = "
                                "\"<a long random string>\" (e.g. from `openssl rand -hex 16`) or listen on "
                                "127.0.0.1")
        if self.kiosk_token and not self.token:
            raise bad("kiosk_token", "is set but token is not: the operator's page would be open to anyone at "
                                     "this machine, the kiosk's visitors too — set token as well")
        if self.kiosk_token and self.kiosk_token == self.token:
            raise bad("kiosk_token", "is the operator token: a kiosk would reach the operator's controls — "
                                     "give the kiosk a token of its own")
        for key in ("token", "kiosk_token"):
            value = getattr(self, key)
            if value != value.strip() or any(not c.isprintable() for c in value):
                raise bad(key, "must be printable without spaces at its ends (it travels in a URL and a header)")
        for key, low, high in (("update_hz", 1, 100), ("slider_hz", 1, 100), ("timeout", 0.1, 60)):
            if not low <= getattr(self, key) <= high:
                raise bad(key, f"{getattr(self, key):g} must be in [{low}, {high}]")
        if not 0 < self.speed <= 1:
            raise bad("speed", f"{self.speed:g} must be in (0, 1] (a fraction of each joint's max speed)")
        if not self.robots:
            raise bad("robots", "is empty: give robot names or \"*\" (every robot)")
        for pattern in self.robots:
            if not pattern or "/" in pattern:
                raise bad("robots", f"{pattern!r} is not a robot name or glob (\"pepper\", \"pepper*\", \"*\")")
        if self.queue < 1:
            raise bad("queue", f"{self.queue} must be at least 1")
        object.__setattr__(self, "stand", _kiosk(self.kiosk))

    def button(self, button_id: str) -> Button | None:
        return next((b for b in self.stand.buttons if b.id == button_id), None)


def _kiosk(table: dict[str, Any]) -> Kiosk:
    try:
        raw = dict(table)
        buttons = raw.pop("buttons", [])
        if not isinstance(buttons, list) or not all(isinstance(b, dict) for b in buttons):
            raise ConfigError("'buttons' must be [[...kiosk.buttons]] tables")
        kiosk = from_mapping(Kiosk, raw, "kiosk")
        kiosk = Kiosk(kiosk.robot, tuple(from_mapping(Button, b, f"kiosk.buttons[{i}]")
                                          for i, b in enumerate(buttons)))
    except ConfigError as exc:
        raise bad("kiosk", str(exc)) from None
    ids = [b.id for b in kiosk.buttons]
    if len(set(ids)) != len(ids):
        raise bad("kiosk", f"button id {next(i for i in ids if ids.count(i) > 1)!r} is given twice — ids are "
                           "what the page presses: make them unique")
    if kiosk.buttons and not kiosk.robot:
        raise bad("kiosk", "has buttons but no robot — add robot = \"pepper\" (the robot they command)")
    if kiosk.robot:
        try:
            keys.check_name("robot", kiosk.robot)
        except ValueError as exc:
            raise bad("kiosk", f"{exc}") from None
    return kiosk


def loopback(host: str) -> bool:
    """Whether ``host`` (an address or a name) is only this machine."""
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        pass
    try:
        found = socket.getaddrinfo(host, None, type=socket.SOCK_STREAM)
    except (socket.gaierror, UnicodeError):
        return False  # (the server's start names an unresolvable host)
    return all(ipaddress.ip_address(str(info[4][0]).split("%")[0]).is_loopback for info in found)
