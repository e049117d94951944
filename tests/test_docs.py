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
from sonibus.bus import config, installed, registry, runner

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


def test_the_readme_lists_every_adapter_sonibus_ships_as_sonibus_adapters_does():
    """Issue 19, item 5: the README's adapter list lacked features."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    block = text.partition("    sonibus adapters\n")[2].partition("\n\n")[0]
    listed = dict(line.strip().split(None, 1) for line in block.splitlines())
    ours = {name for name, ep in installed.available().items() if installed.package(ep) == "sonibus"}
    assert set(listed) == ours
    for name, summary in listed.items():
        assert summary == registry.summary(registry.load(name)), name
