"""``Bus`` (bus/node.py) is the only way out: no other module of the package touches
a Zenoh session — it declares nothing, puts and gets nothing on a session itself.
(bus/session.py opens sessions and reads who they reached, for ``Bus``.)"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = [p for d in ("bus", "adapters") for p in sorted((ROOT / d).rglob("*.py"))]
ALLOWED = {ROOT / "bus" / "node.py", ROOT / "bus" / "session.py"}
SESSION_CALLS = {"declare_publisher", "declare_subscriber", "declare_queryable", "declare_querier",
                 "liveliness", "declare_token"}


def touches(source: str) -> list[str]:
    """What in ``source`` reaches a Zenoh session around ``Bus``, as 'line: code'."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Attribute):
            owner = node.value
            bus_session = node.attr == "session" and (
                (isinstance(owner, ast.Name) and owner.id in ("bus", "_bus"))
                or (isinstance(owner, ast.Attribute) and owner.attr in ("bus", "_bus")))
            if bus_session or node.attr in SESSION_CALLS:
                found.append(f"{node.lineno}: {ast.unparse(node)}")
        elif isinstance(node, ast.Call) and ast.unparse(node.func) == "zenoh.open":
            found.append(f"{node.lineno}: {ast.unparse(node)}")
    return found


def test_no_module_but_bus_touches_a_session():
    offenders = {str(p.relative_to(ROOT)): hits for p in PACKAGE if p not in ALLOWED
                 if (hits := touches(p.read_text(encoding="utf-8")))}
    assert not offenders, offenders


def test_the_check_finds_a_session_used_around_bus():
    sneaky = ("def start(self):\n"
              "    self.bus.session.put('a/b', b'x')\n"
              "    p = bus.session\n"
              "    q = session.declare_publisher('a')\n"
              "    s = zenoh.open(config)\n")
    assert sorted(hit.split(":")[0] for hit in touches(sneaky)) == ["2", "3", "4", "5"]
    assert touches("self.session.call('ALMotion')\nbus.put('a', {})\n") == []  # a libqi session; a Bus call
    assert len(PACKAGE) > 50
