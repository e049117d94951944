"""Foxglove's published JSON Schemas that sonibus writes messages of, vendored
unchanged from the foxglove-sdk repository (``SOURCES``), so recordings and the
live ``foxglove`` adapter name them exactly as Foxglove's panels expect.

>>> from sonibus.schemas import foxglove
>>> foxglove.load("foxglove.Log")["title"], sorted(foxglove.SOURCES)
('foxglove.Log', ['foxglove.FrameTransforms', 'foxglove.Log'])
"""

from __future__ import annotations

import json
from functools import cache
from importlib import resources
from typing import Any

__all__ = ["SOURCES", "data", "load"]

_REPO = "https://github.com/foxglove/foxglove-sdk/blob"
SOURCES = {  # schema name → where its file was taken from
    "foxglove.Log": f"{_REPO}/40ea5ebec26678aeca786d5480f6316ba94de05a/schemas/jsonschema/Log.json",
    "foxglove.FrameTransforms":
        f"{_REPO}/c2981a4ad0bc7a30490b8e3598322ff736f2e73b/schemas/jsonschema/FrameTransforms.json",
}


@cache
def data(name: str) -> bytes:
    """The schema file of ``name`` (``foxglove.Log``) as published; ``KeyError`` for another name."""
    if name not in SOURCES:
        raise KeyError(f"no vendored Foxglove schema '{name}' — sonibus has {', '.join(sorted(SOURCES))}")
    return resources.files(__package__).joinpath(name.removeprefix("foxglove.") + ".json").read_bytes()


def load(name: str) -> dict[str, Any]:
    """The schema ``name`` as a dict."""
    return json.loads(data(name))
