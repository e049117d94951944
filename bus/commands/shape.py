"""Command requests shaped from what a surface sends: the words of the command line,
an OSC message's arguments, a JSON object from a browser.

The verb's request schema (``schemas/v1/cmd/``) says how: its properties in order
(the order OSC arguments come in, and "argument N" in errors) and its main value
(``x-positional``: say's text, a posture's name), which takes loose words or a run
of OSC strings joined by spaces, since Pure Data splits a message into words. The
same mistake gives the same ``CommandError("bad_request", ...)`` from every surface.
A verb without a schema is passed on with no arguments (its robot answers
``unknown_verb`` with the list), and a verb whose schema takes anything (``stop``)
ignores what it is given (a button's 1.0). Only the shape is checked here; ranges,
joints, behaviors and postures are the robot owner's (``commands.validate``).
Requests to a program that drives a robot (``section="program"``: a show's
``scenario``) are shaped the same way from their schemas in ``schemas/v1/program/``.

>>> from_words("say", ["hello", "there", "volume=0.5"])
{'text': 'hello there', 'volume': 0.5}
>>> from_words("say", ["1+1=2"])
{'text': '1+1=2'}
>>> from_osc("scenario", ["hello"], section="program")
{'name': 'hello'}
>>> from_osc("say", ["hello", "there", 0.5])
{'text': 'hello there', 'volume': 0.5}
>>> from_json("say", {"volume": 0.5, "text": "hello there"})
{'text': 'hello there', 'volume': 0.5}
>>> from_osc("joints/set", ["HeadYaw", 0.3, "HeadPitch", -0.1, 0.5])
{'names': ['HeadYaw', 'HeadPitch'], 'angles': [0.3, -0.1], 'speed': 0.5}
>>> from_osc("stiffness", ["Head", "LArm", 1])
{'names': ['Head', 'LArm'], 'value': 1.0}
>>> for shape, given in [(from_words, ["hi", "volume=0.5", "speed=fast"]), (from_osc, ["hi", 0.5, "fast"]),
...                      (from_json, {"text": "hi", "volume": 0.5, "speed": "fast"})]:
...     try:
...         shape("say", given)
...     except CommandError as exc:
...         print(exc)
say: argument 3 (speed) must be a number, got string 'fast' — give a number, e.g. speed=225
say: argument 3 (speed) must be a number, got string 'fast' — give a number, e.g. speed=225
say: argument 3 (speed) must be a number, got string 'fast' — give a number, e.g. speed=225
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cache
from typing import Any

from ... import schemas
from ..errors import CommandError

WANTED = {"number": "a number", "integer": "an integer", "string": "a string", "boolean": "T, F, 0 or 1"}
TRUE_WORDS = ("true", "t", "1", "on", "yes")
FALSE_WORDS = ("false", "f", "0", "off", "no")
TYPE_NAMES = {"str": "string", "list": "array", "tuple": "MIDI or time tag", "dict": "object"}


@dataclass(frozen=True)
class Argument:
    """One argument of a verb, as its request schema declares it."""

    name: str
    place: int            # 1, 2, ...: its place among the schema's properties
    kind: str             # the JSON Schema type: number, integer, string, boolean or array
    items: str = ""       # an array's item type
    required: bool = False
    positional: bool = False
    example: str = ""     # how a good value looks, in errors ("" when its kind says enough)

    @property
    def wanted(self) -> str:
        return f"a list of {self.items}s" if self.kind == "array" else WANTED.get(self.kind, self.kind)

    @property
    def hint(self) -> str:
        return f", e.g. {self.name}={self.example}" if self.example else ""


@dataclass(frozen=True)
class Signature:
    """A verb's arguments in order; ``takes_any``: its schema takes any (they are ignored)."""

    verb: str
    arguments: tuple[Argument, ...]
    takes_any: bool = False

    def get(self, name: str) -> Argument | None:
        return next((a for a in self.arguments if a.name == name), None)

    @property
    def positional(self) -> Argument | None:
        return next((a for a in self.arguments if a.positional), None)

    @property
    def names(self) -> str:
        return ", ".join(a.name for a in self.arguments) or "none"


@cache
def signature(verb: str, section: str = "cmd") -> Signature | None:
    """The arguments ``verb`` takes (a robot's command; ``section="program"``: a request
    to a program that drives the robot, such as a show's ``scenario``); None for a verb
    with no request schema."""
    if verb not in schemas.request_verbs(section):
        return None
    schema = schemas.request_schema(section, verb)
    props = schema.get("properties", {})
    required = set(schema.get("required", ()))
    arguments = tuple(
        Argument(name, place, prop.get("type", ""), prop.get("items", {}).get("type", ""), name in required,
                 name == schema.get("x-positional"), _example(prop))
        for place, (name, prop) in enumerate(props.items(), 1))
    return Signature(verb, arguments, takes_any=not props and schema.get("additionalProperties") is not False)


def _example(prop: dict[str, Any]) -> str:
    """A good value of a number (its default, or the middle of its range), or a list of numbers."""
    if prop.get("type") == "array" and prop.get("items", {}).get("type") in ("number", "integer"):
        return "[0.3,-0.1]"
    if prop.get("type") not in ("number", "integer"):
        return ""
    if "default" in prop:
        return f"{prop['default']:g}"
    low = prop.get("minimum", prop.get("exclusiveMinimum"))
    high = prop.get("maximum", prop.get("exclusiveMaximum"))
    return f"{(low + high) / 2:g}" if low is not None and high is not None else "1"


# -- the three surfaces --------------------------------------------------------------


def from_words(verb: str, words: Sequence[str], section: str = "cmd") -> dict[str, Any]:
    """The request of command-line words: ``NAME=VALUE``, loose words for the main
    value, comma-separated lists (``names=HeadYaw,HeadPitch``)."""
    sig = signature(verb, section)
    if sig is None or sig.takes_any:
        return {}
    main = sig.positional
    main_named = main is not None and any(w.startswith(main.name + "=") for w in words)
    named = [w for w in words if ("=" in w.split(" ", 1)[0] if main_named else _is_named(sig, w))]
    loose = [w for w in words if w not in named]
    texts: dict[str, str] = {}
    if loose and main_named:
        raise _bad(f"{verb}: {main.name} given twice: {' '.join(loose)!r} and {main.name}=...")
    if loose:
        if main is None:
            takes = f"takes only NAME=VALUE arguments: {sig.names}" if sig.arguments else "takes no arguments"
            raise _bad(f"{verb} {takes}, got {' '.join(loose)!r}")
        if main.kind != "string" and len(loose) > 1:
            raise _bad(f"{verb} takes one {main.name}, got {' '.join(loose)!r}")
        texts[main.name] = " ".join(loose)
    for word in named:
        name, _, text = word.partition("=")
        texts[_known(sig, name).name] = text
    return _request(sig, texts, _from_text)


def _is_named(sig: Signature, word: str) -> bool:
    """``NAME=VALUE``, unless NAME is no argument and the verb's main value is text
    (``say 1+1=2``); a NAME close to an argument's is refused as a typo."""
    name, sep, _ = word.split(" ", 1)[0].partition("=")
    main = sig.positional
    if not sep or sig.get(name) or main is None or main.kind != "string":
        return bool(sep)
    if difflib.get_close_matches(name, [a.name for a in sig.arguments], n=1):
        _known(sig, name)  # raises, as from every surface
    return False


def from_osc(verb: str, args: Sequence[Any], section: str = "cmd") -> dict[str, Any]:
    """The request of an OSC message's arguments, in the order of the verb's
    arguments; an array (and the main string) takes a run of strings, joints/set
    takes ``"Joint" angle`` pairs and an optional speed."""
    sig = signature(verb, section)
    if sig is None or sig.takes_any:
        return {}
    if verb == "joints/set":
        return _request(sig, _joint_pairs(verb, args), _from_value)
    values: dict[str, Any] = {}
    index = 0
    for arg in sig.arguments:
        if index >= len(args):
            break
        if arg.kind == "array" or (arg.positional and arg.kind == "string"):
            run = 0
            while index + run < len(args) and isinstance(args[index + run], str):
                run += 1
            words = list(args[index:index + run]) if run else args[index]  # none: refused as it is
            values[arg.name] = " ".join(words) if run and arg.kind == "string" else words
            index += max(run, 1)
        else:
            values[arg.name] = args[index]
            index += 1
    if index < len(args):
        takes = f"takes {' '.join(a.name for a in sig.arguments)}" if sig.arguments else "takes no arguments"
        raise _bad(f"{verb} {takes}: argument {index + 1} ({shown(args[index])}) has no place")
    return _request(sig, values, _from_value)


def from_json(verb: str, value: Any, section: str = "cmd") -> dict[str, Any]:
    """The request of a decoded JSON object, its types checked strictly: numbers
    are numbers (not strings, not booleans), lists are lists."""
    sig = signature(verb, section)
    if sig is None or sig.takes_any:
        return {}
    if not isinstance(value, dict):
        raise _bad(f"{verb}: arguments must be a map, got {shown(value)}")
    for name in value:
        _known(sig, str(name))
    return _request(sig, value, _from_value)


# -- what they share -------------------------------------------------------------------


Reader = Callable[[str, Argument, Any, int], Any]  # verb, argument, raw value, item number (0: none)


def _request(sig: Signature, raw: dict[str, Any], read: Reader) -> dict[str, Any]:
    """``raw`` values typed by ``read``, in the order of the verb's arguments; the first
    missing required argument refused."""
    out: dict[str, Any] = {}
    for arg in sig.arguments:
        if arg.name in raw:
            out[arg.name] = _typed(sig.verb, arg, raw[arg.name], read)
    for arg in sig.arguments:
        if arg.required and arg.name not in out:
            raise _bad(f"{sig.verb}: argument {arg.place} ({arg.name}) is missing — give {arg.wanted}{arg.hint}")
    return out


def _typed(verb: str, arg: Argument, value: Any, read: Reader) -> Any:
    if arg.kind != "array":
        return read(verb, arg, value, 0)
    if read is _from_text:  # "HeadYaw,HeadPitch" or "[0.3,-0.1]"
        value = [t.strip() for t in value.strip().removeprefix("[").removesuffix("]").split(",") if t.strip()]
    if not isinstance(value, list):
        raise _wrong(verb, arg, value)
    return [read(verb, arg, item, number) for number, item in enumerate(value, 1)]


def _from_text(verb: str, arg: Argument, text: str, item: int) -> Any:
    kind = arg.items if item else arg.kind
    try:
        if kind == "number":
            return _finite(verb, arg, float(text), item)
        if kind == "integer":
            return int(text)
    except ValueError:
        raise _wrong(verb, arg, text, item) from None
    if kind == "boolean" and text.lower() in (*TRUE_WORDS, *FALSE_WORDS):
        return text.lower() in TRUE_WORDS
    if kind == "boolean":
        raise _wrong(verb, arg, text, item)
    return text


def _from_value(verb: str, arg: Argument, value: Any, item: int) -> Any:
    """A typed value (OSC, JSON): a boolean is never a number; a number 0 or 1 is a boolean."""
    kind = arg.items if item else arg.kind
    number = _is_number(value)
    try:
        if kind == "number" and number:
            return _finite(verb, arg, float(value), item)
        if kind == "integer" and number and float(value).is_integer():
            return int(value)
    except OverflowError:  # an integer too big for a float
        pass
    if kind == "string" and isinstance(value, str):
        return value
    if kind == "boolean" and (isinstance(value, bool) or (number and value in (0, 1))):
        return bool(value)
    raise _wrong(verb, arg, value, item)


def _finite(verb: str, arg: Argument, value: float, item: int) -> float:
    """``value`` if it is a finite number: NaN and ±inf are refused while the request is shaped,
    by every surface alike (a browser's ``NaN``, OSC's, the word ``nan``), before anything holds it."""
    if not math.isfinite(value):
        which = f" item {item}" if item else ""
        raise _bad(f"{verb}: argument {arg.place} ({arg.name}){which} must be a finite number, got {shown(value)}")
    return value


def _joint_pairs(verb: str, args: Sequence[Any]) -> dict[str, Any]:
    """``"HeadYaw" 0.3 ["HeadPitch" -0.1 ...] [speed]``; names and angles are left
    out when there is no pair (missing, as from the other surfaces)."""
    names: list[str] = []
    angles: list[Any] = []
    index = 0
    while index < len(args) and isinstance(args[index], str):
        after = args[index + 1] if index + 1 < len(args) else None
        if index + 1 >= len(args) or not _is_number(after):
            got = shown(after) if index + 1 < len(args) else "nothing"
            raise _bad(f"{verb}: joint {args[index][:40]!r} (argument {index + 1}) must be followed by its angle, "
                       f"got {got}")
        names.append(args[index])
        angles.append(after)
        index += 2
    out: dict[str, Any] = {"names": names, "angles": angles} if names else {}
    rest = args[index:]
    if len(rest) == 1 and _is_number(rest[0]):
        out["speed"] = rest[0]
    elif rest:
        raise _bad(f"{verb}: expected \"Joint\" angle pairs and an optional speed, argument {index + 1} is "
                   f"{shown(rest[0])}")
    return out


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _known(sig: Signature, name: str) -> Argument:
    arg = sig.get(name)
    if arg is None:
        joint = (f" (for a joint: names={name[:40]} angles=<radians>)"
                 if sig.get("names") is not None and sig.get("angles") is not None else "")
        raise _bad(f"{sig.verb} has no argument {name[:40]!r} — arguments: {sig.names}{joint}")
    return arg


def _wrong(verb: str, arg: Argument, value: Any, item: int = 0) -> CommandError:
    which = f" item {item}" if item else ""
    wanted = WANTED.get(arg.items, arg.items) if item else arg.wanted
    fix = f" — give {arg.wanted}{arg.hint}" if arg.example else ""
    return _bad(f"{verb}: argument {arg.place} ({arg.name}){which} must be {wanted}, got {shown(value)}{fix}")


def _bad(message: str) -> CommandError:
    return CommandError("bad_request", message)


def shown(value: Any) -> str:
    """A value in an error, whichever surface it came from: ``string 'loud'``, ``int 3``,
    ``a blob of 2 bytes``, ``nil``, ``boolean true``."""
    if isinstance(value, bytes):
        return f"a blob of {len(value)} bytes"
    if value is None:
        return "nil"
    if isinstance(value, bool):
        return f"boolean {str(value).lower()}"
    text = repr(value)
    kind = TYPE_NAMES.get(type(value).__name__, type(value).__name__)
    return f"{kind} {text[:40]}{'...' if len(text) > 40 else ''}"
