"""Writing a map node's maps back into its installation file, its comments and layout
kept (tomlkit edits the document in place: only the keys that changed are touched).

>>> text = '''# the show
... [nodes.sound]
... adapter = "map"
... [nodes.sound.maps.cutoff]   # the filter
... source = "pepper/derived/hand/R.z"
... to = [200, 2000]   # Hz
... curve = "exp"
... '''
>>> print(rewritten(text, "sound", {"cutoff": {"source": "pepper/derived/hand/R.z", "to": [200, 4000],
...                                            "curve": "exp", "smooth_ms": 80}}), end="")
# the show
[nodes.sound]
adapter = "map"
[nodes.sound.maps.cutoff]   # the filter
source = "pepper/derived/hand/R.z"
to = [200, 4000]   # Hz
curve = "exp"
smooth_ms = 80

A map removed live and one added:

>>> print(rewritten(text, "sound", {"swing": {"source": "pepper/derived/hand_speed/R"}}, {"cutoff"}), end="")
# the show
[nodes.sound]
adapter = "map"
<BLANKLINE>
[nodes.sound.maps.swing]
source = "pepper/derived/hand_speed/R"
"""

from __future__ import annotations

import os
import tempfile
import tomllib
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import tomlkit
import tomlkit.exceptions
from tomlkit.items import Item


class SaveError(ValueError):
    """The file cannot take the maps (not found, not the node's, not writable): its one-line reason."""


def rewritten(text: str, node: str, tables: dict[str, dict[str, Any]], removed: Iterable[str] = ()) -> str:
    """``text`` (an installation file) with ``[nodes.<node>.maps.<name>]`` set to ``tables``: keys
    changed, added and removed, a map added live a table of its own at the end, maps ``removed``
    live taken out; everything else as it was. Checked: the result reads back to the same maps,
    or ``SaveError``."""
    try:
        doc = tomlkit.parse(text)
    except tomlkit.exceptions.TOMLKitError as exc:
        raise SaveError(f"the file is not valid TOML any more: {exc}") from None
    try:
        maps = doc["nodes"][node]["maps"]  # type: ignore[index]
    except (KeyError, TypeError):
        raise SaveError(f"the file has no [nodes.{node}.maps] (was it changed since the start?)") from None
    gone = [name for name in removed if name not in tables]
    for name in gone:
        if name in maps:
            del maps[name]
    for name, table in tables.items():
        if name not in maps:  # (added live)
            maps[name] = tomlkit.table()
        _update(maps[name], table)
    out = tomlkit.dumps(doc)
    kept = {k: v for k, v in tomllib.loads(text)["nodes"][node]["maps"].items() if k not in gone}
    if tomllib.loads(out)["nodes"][node]["maps"] != {**kept, **tables}:
        raise SaveError("the maps written would not read back as they run (a layout tomlkit cannot edit)")
    return out


def _update(current: Any, table: dict[str, Any]) -> None:
    for key in [k for k in current if k not in table]:
        del current[key]
    for key, value in table.items():
        old = current.get(key)
        if old is None or (old.unwrap() if isinstance(old, Item) else old) != value:
            current[key] = value


def save(path: Path, node: str, tables: dict[str, dict[str, Any]], removed: Iterable[str] = ()) -> None:
    """Rewrite ``path`` with the maps (``rewritten``), atomically: a crash leaves the old file or the new one."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise SaveError(f"cannot read {path}: {exc.strerror}") from None
    out = rewritten(text, node, tables, removed)
    try:
        fd, temp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as file:
                file.write(out)
            os.chmod(temp, path.stat().st_mode & 0o7777)
            os.replace(temp, path)
        except BaseException:
            os.unlink(temp)
            raise
    except OSError as exc:
        raise SaveError(f"cannot write {path}: {exc.strerror}") from None
