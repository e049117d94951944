"""``sonibus top``'s tables as drawn: a cell that grows wider than its column had been
(a node's rx/s from 852 to 2,150 when a robot joins) is shown whole, not cropped."""

from __future__ import annotations

import asyncio

from rich.text import Text
from textual.app import App, ComposeResult
from textual.widgets import DataTable

from sonibus.bus.cli.top import _fill


class Table(App[None]):
    def compose(self) -> ComposeResult:
        yield DataTable[Text]()


def test_a_cell_that_grows_wider_is_shown_whole():
    async def run() -> list[str]:
        app = Table()
        async with app.run_test(size=(80, 6)) as pilot:
            table = app.query_one(DataTable)
            for name in ("rx/s", "node"):
                table.add_column(name, key=name)
            _fill(table, [("web", [Text("852"), Text("web")])])
            await pilot.pause()
            _fill(table, [("web", [Text("2,150"), Text("web")])])
            await pilot.pause()
            return ["".join(segment.text for segment in table.render_line(y)) for y in range(2)]

    _, line = asyncio.run(run())
    assert line.split() == ["2,150", "web"], line
