"""The key space (see docs/design.md, "Key space")."""

from __future__ import annotations

from dataclasses import dataclass

import zenoh

from .errors import ConfigError, controls, visible

NODES = "sonibus/nodes"
ROBOTS = "sonibus/robots"
NODE_EVENTS = "sonibus/events/node"  # a node's state changes (a worker failed, a restart): an event like a robot's
STATS = "sonibus/stats"
NODE_STATS = f"{STATS}/*/*"  # every node's stats (bus/stats.py, bus/health.py)


def joint(robot: str, name: str) -> str:
    return f"{robot}/joints/{name}"


def joints(robot: str = "*") -> str:
    return f"{robot}/joints/*"


def frame(robot: str = "*") -> str:
    """Where a robot owner publishes each frame whole (every joint of one instant)."""
    return f"{robot}/frame"


def is_frame(key: str) -> bool:
    """Whether ``key`` is a robot's frame key (``pepper/frame``)."""
    return key.endswith("/frame") and key.count("/") == 1


def derived(robot: str, feature: str, name: str) -> str:
    return f"{robot}/derived/{feature}/{name}"


def derived_frame(robot: str = "*") -> str:
    """Where a feature processor publishes every derived value of one frame in one message
    (``pepper/derived``: under ``*/derived/**``, so subscriptions to derived keys see it)."""
    return f"{robot}/derived"


def is_derived_frame(key: str) -> bool:
    """Whether ``key`` is a robot's derived frame key (``pepper/derived``)."""
    return key.endswith("/derived") and key.count("/") == 1


def event(robot: str, kind: str) -> str:
    return f"{robot}/events/{kind}"


AUDIO_STREAMS = ("mic", "speaker")  # a robot's microphones; what it should play


def audio(robot: str, stream: str) -> str:
    """Where ``robot``'s audio ``stream`` (``mic`` or ``speaker``) flows (``bus/audio.py``)."""
    if stream not in AUDIO_STREAMS:
        raise ValueError(f"audio stream '{stream}' is not one of {', '.join(AUDIO_STREAMS)}")
    return f"{robot}/audio/{stream}"


def command(robot: str, verb: str = "**") -> str:
    return f"{robot}/cmd/{verb}"


def command_verb(key: str) -> str:
    """The verb of a command key (``pepper/cmd/joints/set`` → ``joints/set``; ``*/cmd/stop``, a
    query for every robot, → ``stop``); "" when ``key`` names no verb.

    >>> command_verb("*/cmd/stop"), command_verb("pepper/cmd/joints/set"), command_verb("**")
    ('stop', 'joints/set', '')
    """
    _, _, rest = str(key).partition("/")
    section, _, verb = rest.partition("/")
    return verb if section == "cmd" else ""


def is_concrete(key: str) -> bool:
    """Whether ``key`` names one key (no ``*``, ``$*`` or ``**`` in it)."""
    return "*" not in key and "$" not in key


def program(robot: str, verb: str = "**") -> str:
    """Where a program that drives ``robot`` through its commands (a show) takes requests
    of its own (``pepper/program/scenario``): a queryable that program serves, never the owner."""
    return f"{robot}/program/{verb}"


def maps(node: str, verb: str = "**") -> str:
    """Where a map node takes requests about its maps (``sound/maps/edit``: list, edit, learn,
    undo, save; ``adapters/map/edit.py``): a queryable it serves."""
    return f"{node}/maps/{verb}"


def info(robot: str) -> str:
    return f"{robot}/info"


def derived_info(robot: str) -> str:
    """Where feature processors describe the derived keys they publish for ``robot``."""
    return f"{robot}/info/derived"


def node_token(host: str, node: str) -> str:
    return f"{NODES}/{host}/{node}"


def node_stats(host: str, node: str) -> str:
    """Where a node publishes its stats once a second, and serves the latest."""
    return f"{STATS}/{host}/{node}"


def robot_token(robot: str = "*") -> str:
    """The key expression of every owner's token of ``robot`` (``sonibus/robots/<robot>/<since>/<host>/<node>``,
    ``bus/ownership.py``)."""
    return f"{ROBOTS}/{robot}/**"


@dataclass(frozen=True)
class Key:
    """A data key taken apart once: ``pepper/joints/HeadYaw`` → robot ``pepper``,
    section ``joints``, name ``HeadYaw``; ``pepper/derived/hand/RHand`` also has
    feature ``hand``."""

    key: str
    robot: str
    section: str
    name: str
    feature: str = ""

    @classmethod
    def parse(cls, key: str) -> Key:
        robot, _, rest = str(key).partition("/")
        section, _, name = rest.partition("/")
        if not robot or not section:
            raise ValueError(f"not a sonibus data key: '{key}'")
        feature, _, name = name.rpartition("/") if section == "derived" else ("", "", name)
        return cls(str(key), robot, section, name, feature)


NOT_IN_NAMES = "/*$?#@ "  # what a name must not hold to be one plain key chunk


def check_name(kind: str, name: str) -> str:
    """A robot or node name must be one plain key chunk."""
    if not name or any(c in name for c in NOT_IN_NAMES) or controls(name):
        raise ValueError(f"{kind} name '{visible(name)}' must be non-empty without '/', '*', '$', '?', '#', '@', "
                         f"spaces or control characters (a newline...)")
    return name


def expr(pattern: str) -> str:
    """A Zenoh key expression from a user's pattern: ``pepper/joints/R*`` becomes
    ``pepper/joints/R$*`` (Zenoh only allows a bare ``*`` as a whole chunk)."""
    chunks = []
    for chunk in pattern.strip().split("/"):
        if "*" in chunk and chunk not in ("*", "**") and "$*" not in chunk:
            chunk = chunk.replace("*", "$*")
        chunks.append(chunk)
    text = "/".join(chunks)
    try:
        return str(zenoh.KeyExpr.autocanonize(text))
    except Exception as exc:  # zenoh's message carries a Rust source path: keep only its first sentence
        reason = str(exc).split(" at /")[0]
        raise ConfigError(f"'{pattern}' is not a valid key expression: {reason}") from None


def patterns(value: str | tuple[str, ...] | list[str], key: str = "subscribe") -> tuple[str, ...]:
    """A config's ``subscribe`` value (one pattern or several) as checked key expressions;
    ``ConfigError`` naming ``key`` otherwise."""
    found = (value,) if isinstance(value, str) else tuple(value)
    if not found:
        raise ConfigError(f"key '{key}': is empty — give at least one key expression such as \"*/joints/*\"")
    for pattern in found:
        try:
            expr(pattern)
        except ConfigError as exc:
            raise ConfigError(f"key '{key}': {exc}") from None
    return found
