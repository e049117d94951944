"""The whole bus under bad input: Hypothesis sends frames, joint samples, derived
values, events, commands, info queries (and garbage info replies), OSC packets, and
HTTP and WebSocket to the web pages', OSCQuery's and Foxglove's servers — valid,
malformed, hostile, some in bursts of thousands a second — at one ``sonibus run``
holding every built-in node. After each family the process and every node run, each
server serves a new well-behaved client, and valid data flows again at its normal
rate; at the end no command from invalid input ran, memory stayed bounded, no server
counted an error of its own, and the recording passes ``info``, ``export``, a full
read and ``replay``. Counts per family go to ``fuzz.json`` in the test's
directory and a one-line summary to stdout (``-s``)."""

from __future__ import annotations

import pytest

from .campaign import CI, campaign


@pytest.mark.external
@pytest.mark.timeout(300)
def test_the_bus_survives_bad_input(show, tmp_path):
    report = campaign(show, CI, tmp_path / "fuzz.json")
    assert not report.problems, (f"{len(report.problems)} problem(s) (counts and first inputs of each kind "
                                 f"in {tmp_path / 'fuzz.json'}):\n- " + "\n- ".join(report.problems))
