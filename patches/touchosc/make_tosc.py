"""Write sonibus.tosc: a TouchOSC (2022+, "Mk2") control surface for the OSC command
gateway, built from the robot's model (bus/robots.json) and the simulator's behaviors,
so that every fader spans its joint's limits.

    .venv/bin/python patches/touchosc/make_tosc.py [--robot pepper] [--output FILE]

A .tosc file is zlib-compressed XML (``<lexml>``): a root GROUP node whose children
are BUTTON, FADER and LABEL nodes, each with ``<properties>``, ``<values>`` and, for
what sends, ``<messages><osc>``: a trigger, the address as ``<path>`` partials and
the ``<arguments>`` partials (a constant, or the control's ``x`` scaled from 0..1 to
``scaleMin``..``scaleMax``). Keys and strings are CDATA, as TouchOSC writes them.
"""

from __future__ import annotations

import argparse
import uuid
import zlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from sonibus.adapters.sim.behaviors import LIBRARY
from sonibus.bus import load_model
from sonibus.bus.robot import RobotModel

HERE = Path(__file__).resolve().parent
WIDTH, HEIGHT = 1024, 768
FADER_JOINTS = ("HeadYaw", "HeadPitch", "LShoulderPitch", "RShoulderPitch", "LElbowRoll", "RElbowRoll")
SAY = "Hello from TouchOSC"
CONNECTION = "10000"  # connection 1 only (lexml 3 has five): set it to the gateway's host and port

Color = tuple[float, float, float, float]
Frame = tuple[float, float, float, float]
Value = float | str | tuple[float, ...]  # a property's value
GREY, BLUE, GREEN, ORANGE, RED = (0.25, 0.25, 0.25, 1.0), (0.2, 0.45, 0.8, 1.0), (0.25, 0.65, 0.35, 1.0), \
    (0.95, 0.55, 0.15, 1.0), (0.85, 0.1, 0.1, 1.0)


@dataclass(frozen=True)
class Partial:
    """One piece of an address or one argument: a constant, or a value of the control."""

    type: str            # CONSTANT | VALUE
    conversion: str      # STRING | FLOAT
    value: str           # the constant, or the value's key ("x")
    scale_min: float = 0.0
    scale_max: float = 1.0


@dataclass(frozen=True)
class Osc:
    """What a control sends, and when (``RISE``: on press; ``ANY``: on every change)."""

    address: str
    arguments: tuple[Partial, ...]
    condition: str


@dataclass(frozen=True)
class Control:
    kind: str            # BUTTON | FADER | LABEL
    name: str
    frame: Frame
    color: Color
    osc: Osc | None = None
    x: float = 0.0       # the value it starts at
    text: str = ""       # a label's text
    text_size: int = 14


def controls(robot: str, model: RobotModel) -> list[Control]:
    """Every control of the surface, in drawing order (a label after what it names)."""
    cmd = f"/{robot}/cmd/"
    out = [Control("LABEL", "title", (20, 8, 984, 40), GREY,
                   text=f"sonibus · {robot} · OSC gateway, UDP port 9001", text_size=20)]

    def button(name: str, frame: Frame, color: Color, verb: str, *args: str, label: str, size: int = 14) -> None:
        constants = tuple(Partial("CONSTANT", "STRING", a) for a in args)
        out.append(Control("BUTTON", name, frame, color, Osc(cmd + verb, constants, "RISE")))
        out.append(Control("LABEL", f"{name}_label", frame, color, text=label, text_size=size))

    out.append(Control("LABEL", "behaviors", (20, 56, 480, 24), GREY, text="Behaviors"))
    for i, behavior in enumerate(LIBRARY):
        frame = (20 + (i % 2) * 245, 84 + (i // 2) * 68, 235, 60)
        button(f"behavior_{i + 1}", frame, BLUE, "behavior/run", behavior, label=behavior.rpartition("/")[2])
    out.append(Control("LABEL", "postures", (20, 360, 480, 24), GREY, text="Postures"))
    for i, posture in enumerate(model.postures):  # four a row (NAO has eight)
        button(f"posture_{posture}", (20 + i % 4 * 122, 388 + i // 4 * 68, 112, 60), GREEN, "posture", posture,
               label=posture)
    y = 388 + (len(model.postures) + 3) // 4 * 68 + 14
    button("say", (20, y, 480, 60), BLUE, "say", SAY, label=f"say “{SAY}”")
    button("behavior_stop", (20, y + 80, 480, 60), GREY, "behavior/stop", label="stop the behavior")

    start = model.posture("StandInit")
    joints = [j for j in FADER_JOINTS if model.has_joint(j)]
    out.append(Control("LABEL", "joints", (520, 56, 484, 24), GREY, text="Joints (rad)"))
    for i, joint in enumerate(joints):
        spec = model.joint(joint)
        value = Partial("VALUE", "FLOAT", "x", spec.min, spec.max)
        frame = (520 + i * 82, 84, 70, 420)
        x = (min(max(start.get(joint, 0.0), spec.min), spec.max) - spec.min) / (spec.max - spec.min)
        out.append(Control("FADER", f"fader_{joint}", frame, ORANGE, Osc(cmd + f"joints/set/{joint}", (value,), "ANY"),
                           x=round(x, 6)))
        out.append(Control("LABEL", f"fader_{joint}_label", (frame[0] - 6, 508, 82, 40), GREY,
                           text=f"{joint}\n{spec.min:.2f} … {spec.max:.2f}", text_size=10))
    button("stop", (520, 580, 484, 168), RED, "stop", label="STOP", size=48)
    return out


# -- the XML ------------------------------------------------------------------------

def _num(value: float) -> str:
    return str(int(value)) if float(value).is_integer() else repr(float(value))


def _cdata(text: str) -> str:
    if "]]>" in text:
        raise ValueError(f"{text!r} cannot be written as CDATA")
    return f"<![CDATA[{text}]]>"


def _property(kind: str, key: str, value: Value) -> str:
    if isinstance(value, tuple):  # a frame (x y w h) or a color (r g b a)
        body = "".join(f"<{k}>{_num(v)}</{k}>" for k, v in zip("xywh" if kind == "r" else "rgba", value, strict=True))
    else:
        body = _cdata(value) if isinstance(value, str) else _num(value)
    return f"<property type='{kind}'><key>{_cdata(key)}</key><value>{body}</value></property>"


def _properties(control: Control) -> dict[str, tuple[str, Value]]:
    """TouchOSC's properties for a new control of this kind, with ours set."""
    props: dict[str, tuple[str, Value]] = {
        "background": ("b", 1), "color": ("c", control.color), "cornerRadius": ("f", 4.0),
        "frame": ("r", control.frame), "grabFocus": ("b", 1), "interactive": ("b", 1), "locked": ("b", 0),
        "name": ("s", control.name), "orientation": ("i", 0), "outline": ("b", 1), "outlineStyle": ("i", 1),
        "pointerPriority": ("i", 0), "shape": ("i", 1), "visible": ("b", 1),
    }
    if control.kind == "BUTTON":
        props |= {"buttonType": ("i", 0), "press": ("b", 1), "release": ("b", 1), "valuePosition": ("b", 0)}
    elif control.kind == "FADER":
        props |= {"bar": ("b", 1), "barDisplay": ("i", 0), "cursor": ("b", 1), "cursorDisplay": ("i", 0),
                  "grid": ("b", 1), "gridColor": ("c", (0.0, 0.0, 0.0, 0.25)), "gridSteps": ("i", 13),
                  "response": ("i", 0), "responseFactor": ("i", 100)}
    elif control.kind == "LABEL":  # drawn over a button, a label must let the touch through
        props |= {"background": ("b", 0), "font": ("i", 0), "grabFocus": ("b", 0), "interactive": ("b", 0),
                  "outline": ("b", 0), "textAlignH": ("i", 2), "textAlignV": ("i", 2), "textClip": ("b", 1),
                  "textColor": ("c", (1.0, 1.0, 1.0, 1.0)), "textLength": ("i", 0),
                  "textSize": ("i", control.text_size)}
    return props


def _value(key: str, default: str) -> str:
    return (f"<value><key>{_cdata(key)}</key><locked>0</locked><lockedDefaultCurrent>0</lockedDefaultCurrent>"
            f"<default>{_cdata(default)}</default><defaultPull>0</defaultPull></value>")


def _partials(tag: str, partials: tuple[Partial, ...]) -> str:
    return f"<{tag}>" + "".join(
        f"<partial><type>{p.type}</type><conversion>{p.conversion}</conversion><value>{_cdata(p.value)}</value>"
        f"<scaleMin>{_num(p.scale_min)}</scaleMin><scaleMax>{_num(p.scale_max)}</scaleMax></partial>"
        for p in partials) + f"</{tag}>"


def _osc(osc: Osc) -> str:
    return (f"<messages><osc><enabled>1</enabled><send>1</send><receive>0</receive><feedback>0</feedback>"
            f"<connections>{CONNECTION}</connections>"
            f"<triggers><trigger><var>{_cdata('x')}</var><condition>{osc.condition}</condition></trigger></triggers>"
            + _partials("path", (Partial("CONSTANT", "STRING", osc.address),))
            + _partials("arguments", osc.arguments) + "</osc></messages>")


def _node(control: Control) -> Iterator[str]:
    ident = uuid.uuid5(uuid.NAMESPACE_URL, f"sonibus/touchosc/{control.name}")
    yield f"<node ID='{ident}' type='{control.kind}'><properties>"
    yield from (_property(kind, key, value) for key, (kind, value) in sorted(_properties(control).items()))
    yield "</properties><values>"
    if control.kind == "LABEL":
        yield _value("text", control.text)
    else:
        yield _value("x", _num(control.x))
    yield _value("touch", "false")
    yield "</values>"
    if control.osc is not None:
        yield _osc(control.osc)
    yield "</node>"


def document(robot: str, model: RobotModel) -> str:
    """The whole layout as TouchOSC's XML (lexml version 3, which every TouchOSC 2022+ opens)."""
    root = Control("GROUP", "sonibus", (0, 0, WIDTH, HEIGHT), (0.08, 0.08, 0.08, 1.0))
    props = _properties(root) | {"grabFocus": ("b", 0), "interactive": ("b", 0), "outline": ("b", 0),
                                 "outlineStyle": ("i", 0), "cornerRadius": ("f", 0.0)}
    parts = ["<?xml version='1.0' encoding='UTF-8'?><lexml version='3'>",
             f"<node ID='{uuid.uuid5(uuid.NAMESPACE_URL, 'sonibus/touchosc')}' type='GROUP'><properties>",
             *(_property(kind, key, value) for key, (kind, value) in sorted(props.items())),
             "</properties><values>", _value("touch", "false"), "</values><children>"]
    for control in controls(robot, model):
        parts.extend(_node(control))
    parts.append("</children></node></lexml>")
    return "".join(parts)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", default="pepper", help="the robot's bus name (default: pepper)")
    parser.add_argument("--model", default="", help="pepper or nao (default: the robot name without digits)")
    parser.add_argument("--output", type=Path, default=HERE / "sonibus.tosc", help="the .tosc file to write")
    args = parser.parse_args()
    model = load_model(args.model or args.robot.rstrip("0123456789"))
    args.output.write_bytes(zlib.compress(document(args.robot, model).encode("utf-8")))
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
