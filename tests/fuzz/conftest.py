"""The show under fuzz: one ``sonibus run`` holding every built-in node (``show.py``),
ended with everything it started, also when the test fails."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from ..conftest import require_tool
from .show import Show, ShowError


@pytest.fixture
def show(tmp_path: Path) -> Iterator[Show]:
    for tool, package in (("jackd", "jackd2"), ("oscdump", "liblo-tools")):
        require_tool(tool, package)
    try:
        with Show(tmp_path) as running:
            yield running
    except ShowError as exc:
        pytest.fail(str(exc))
