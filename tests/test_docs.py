"""The examples in docstrings and docs run, and the shipped configurations load."""

from __future__ import annotations

import doctest
import importlib
import pkgutil
from pathlib import Path

import pytest

import sonibus.adapters
import sonibus.bus
import sonibus.schemas
from sonibus.bus import config, runner

ROOT = Path(__file__).resolve().parent.parent


def modules() -> list[str]:
    names = ["sonibus.schemas"]
    for package in (sonibus.bus, sonibus.adapters):
        names.append(package.__name__)
        names += [m.name for m in pkgutil.walk_packages(package.__path__, package.__name__ + ".")]
    return names


@pytest.mark.parametrize("name", modules())
def test_docstring_examples_run(name):
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS)
    assert result.failed == 0


@pytest.mark.parametrize("path", [*sorted((ROOT / "examples").glob("*.toml")), ROOT / "adapters" / "demo.toml"],
                         ids=lambda p: p.name)
def test_shipped_installation_files_load_and_build(path):
    adapters = runner.build(config.load(path))
    assert adapters and all(a.state == "new" for a in adapters)
