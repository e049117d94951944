"""Which key expressions a sink subscribes to for the patterns it asks for (``bus/streams.py``
takes what comes of them): joint keys from the robots' frames, derived values from their
derived frames, the sections taken only by name (audio, stats) left out unless named.

>>> plan(["*/joints/*", "*/events/*"])
Plan(frames=('*/frame',), keys=('*/events/*',), broad=(), derived=())
>>> plan(["pepper/**"]).broad, plan(["pepper/joints/R*"], per_joint_keys=True).keys
(('pepper/joints/**',), ('pepper/joints/R$*',))
>>> plan(["*/derived/**", "pepper/derived/qom/*"])  # (the derived frames on their own, not under */derived/**)
Plan(frames=(), keys=('*/derived/*/**', 'pepper/derived/qom/*'), broad=(), derived=('*/derived',))
"""


from __future__ import annotations

import itertools
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import zenoh

from . import keys, messages
from .errors import ConfigError

_JOINTS = zenoh.KeyExpr(keys.joints())
_DERIVED = zenoh.KeyExpr("*/derived/*/*/**")  # every derived value's own key



@dataclass(frozen=True)
class Plan:
    """Key expressions to subscribe to: ``frames`` (frame keys), ``keys`` (as given,
    without frame keys) and ``broad`` (patterns that select joints and more:
    subscribed without their joint and frame keys, which come from ``frames``);
    ``derived``: the derived frame keys of the patterns that select derived values
    (``keys`` and ``broad`` are subscribed without them)."""

    frames: tuple[str, ...] = ()
    keys: tuple[str, ...] = ()
    broad: tuple[str, ...] = ()
    derived: tuple[str, ...] = ()

    @property
    def keyexprs(self) -> tuple[str, ...]:
        """Every key expression it subscribes to, the broadest first (those of every robot, then
        of one): the order ``Streams`` subscribes in, so that one of its own subscriptions a
        broader one includes is served by that one's Zenoh subscriber (``bus/fanout.py``)."""
        return tuple(sorted((*self.frames, *self.derived, *self.keys, *self.broad), key=narrowness))


def plan(patterns: Iterable[str], per_joint_keys: bool = False) -> Plan:
    """How to subscribe to ``patterns`` (user patterns; see ``keys.expr``)."""
    frames: list[str] = []
    direct: list[str] = []
    broad: list[str] = []
    derived: list[str] = []
    for pattern in dict.fromkeys(n for p in patterns for n in narrowed(keys.expr(p))):
        selected = zenoh.KeyExpr(pattern)
        key = keys.derived_frame(_robot(pattern))
        if named_section(pattern) in ("", "derived") and selected.intersects(_DERIVED):
            if key not in derived:
                derived.append(key)
            if pattern.endswith("/derived/**"):  # (``**`` is also no chunk: the derived frame would come twice,
                pattern = pattern[:-2] + "*/**"  # once to be skipped; it comes from ``derived``'s subscription)
        if per_joint_keys or not selected.intersects(_JOINTS):
            direct.append(pattern)  # (subscribed without frame keys: pepper/** would take them twice)
            continue
        frame = keys.frame(_robot(pattern))
        if frame not in frames:
            frames.append(frame)
        if not _JOINTS.includes(selected):  # it selects more than joints
            broad.append(pattern)
    return Plan(_one_each(frames, keys.frame()), tuple(direct), tuple(broad), _one_each(derived, keys.derived_frame()))


def planned(config: Any) -> tuple[str, ...]:
    """The key expressions a node whose configuration has ``subscribe`` (patterns; and
    ``per_joint_keys``) subscribes to through ``Streams`` (the OSC, MIDI, Foxglove and recorder
    nodes), for ``Bus.plan`` (the runner's, before any node starts): () for a configuration
    without, or with patterns its node will refuse. (A node whose ``subscribe`` meant anything
    else would only make others share a broader Zenoh subscriber: nothing any node takes changes.)"""
    patterns = getattr(config, "subscribe", None)
    if not isinstance(patterns, tuple | list) or not all(isinstance(p, str) for p in patterns):
        return ()
    try:
        return plan(patterns, bool(getattr(config, "per_joint_keys", False))).keyexprs
    except (ConfigError, ValueError):  # (said by the node itself when it starts)
        return ()


def narrowness(keyexpr: str) -> int:
    """0 for a key expression of every robot (``*/frame``), 1 for one robot's."""
    return 0 if "*" in keyexpr.split("/")[0] else 1


def _robot(pattern: str) -> str:
    robot = pattern.split("/")[0]
    return "*" if "**" in robot else robot


def _one_each(frames: list[str], every: str) -> tuple[str, ...]:
    """Frame keys to subscribe to: ``every`` robot's in one subscription if two overlap, or a
    frame would come twice (``accepts()`` keeps the robots asked)."""
    if any(zenoh.KeyExpr(a).intersects(zenoh.KeyExpr(b)) for a, b in itertools.combinations(frames, 2)):
        return (every,)
    return tuple(frames)


def frame_keys_of(pattern: str) -> Callable[[str], bool]:
    """What a subscription to ``pattern`` leaves to the frame subscriptions: frame keys, and
    derived frame keys if ``pattern`` selects derived values (``Plan.derived`` has them then)."""
    if not zenoh.KeyExpr(pattern).intersects(_DERIVED):
        return keys.is_frame
    return lambda key: keys.is_frame(key) or keys.is_derived_frame(key)


def from_frames_of(pattern: str) -> Callable[[str], bool]:
    """``frame_keys_of``, and joint keys: what a broad pattern's subscription leaves to the frames."""
    frame_keys = frame_keys_of(pattern)
    return lambda key: frame_keys(key) or (key.count("/") == 2 and key.split("/")[1] == "joints")


def skipping(pattern: str, also: Callable[[str], bool]) -> Callable[[str], bool]:
    """What a subscription to ``pattern`` leaves out: keys ``also`` names, and keys of sections
    taken only by name (audio, nodes' stats) unless ``pattern`` names that section."""
    named = named_section(pattern)

    def skip(key: str) -> bool:
        if also(key):
            return True
        chunks = key.split("/", 2)
        section = messages.SECTIONS.get(chunks[1]) if len(chunks) > 1 else None
        return section is not None and section.by_name and section.name != named

    return skip


def narrowed(pattern: str) -> list[str]:
    """``pattern`` as subscriptions that leave out the sections taken only by name
    (audio, stats) when it does not name them: ``pepper/**`` → ``pepper/joints/**``,
    ``pepper/derived/**``, ... (every key of ours is ``<robot>/<section>/...``, so a
    leading ``**`` is ``*/**`` here; ``**/audio/mic`` names audio and stays).

    >>> narrowed("pepper/*/mic"), narrowed("pepper/audio/mic"), len(narrowed("**"))
    (['pepper/joints/mic', 'pepper/derived/mic', 'pepper/events/mic', 'pepper/info/mic', 'pepper/cmd/mic'], \
['pepper/audio/mic'], 5)
    """
    if named_section(pattern):
        return [pattern]
    chunks = pattern.split("/")
    if chunks[0] == "**":
        chunks = ["*", *chunks] if len(chunks) > 1 else ["*", "**"]
    if len(chunks) < 2 or "*" not in chunks[1]:
        return [pattern]  # a section named after a leading ** (or no robot's key at all)
    robot, section, rest = chunks[0], chunks[1], chunks[2:]
    if section == "**":  # <robot>/**/rest: any section, then what ** stands for past it
        rest = ["**", *rest]
    # (not ``frame``: a pattern's frames come from ``plan``'s frame subscription, or are left out)
    wanted = [name for name, s in messages.SECTIONS.items() if not s.by_name and name != "frame"
              and (section == "**" or zenoh.KeyExpr(section).intersects(zenoh.KeyExpr(name)))]
    return ["/".join([robot, name, *rest]) for name in wanted]


def named_section(pattern: str) -> str:
    """The section ``pattern`` names (``pepper/audio/mic``: ``audio``), or "" (``pepper/**``)."""
    chunks = pattern.split("/")
    return chunks[1] if len(chunks) > 1 and chunks[1] in messages.SECTIONS else ""


def without_audio(patterns: tuple[str, ...], sink: str, key: str = "subscribe") -> tuple[str, ...]:
    """The ``patterns`` of a sink that cannot carry audio (``sink``: "an OSC sink"), unchanged;
    ``ConfigError`` naming ``key`` if one names the audio section (others never bring audio)."""
    for pattern in patterns:
        if named_section(pattern) == "audio":
            raise ConfigError(f"key '{key}': '{pattern}' is audio, which {sink} cannot carry — leave it out "
                              "(the jack adapter plays audio; the recorder records it)")
    return patterns
