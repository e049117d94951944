"""A show's log file on a machine without systemd: every line with its time, rotated
before it grows past its size, the oldest files deleted."""

from __future__ import annotations

import io
import logging
import re

from sonibus.bus.cli import Environment, main
from sonibus.bus.logfile import LogConfig, LogFile

from .conftest import SONIBUS, wait_for


def test_the_file_rotates_at_its_size_and_keeps_the_newest_lines_in_order(tmp_path):
    level = logging.getLogger("sonibus").level
    log_file = LogFile(LogConfig(file=str(tmp_path / "show.log"), max_mb=0.002, keep=2))
    try:
        for i in range(300):
            logging.getLogger("sonibus.test").warning("line %04d %s", i, "x" * 50)
    finally:
        log_file.close()
    files = sorted(p.name for p in tmp_path.iterdir())
    assert files == ["show.log", "show.log.1", "show.log.2"], files
    assert all(p.stat().st_size <= 2000 for p in tmp_path.iterdir())
    lines = [line for name in ("show.log.2", "show.log.1", "show.log")
             for line in (tmp_path / name).read_text().splitlines()]
    numbers = [int(re.search(r"line (\d{4})", line)[1]) for line in lines]
    assert numbers == list(range(numbers[0], 300)) and numbers[0] > 0, numbers  # the newest, in order; the rest gone
    assert re.fullmatch(r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d{3} WARNING sonibus.test: line 0299 x+", lines[-1])
    assert logging.getLogger("sonibus").level == level  # (given back as it was)


def test_sonibus_run_logs_what_it_says_and_its_nodes_to_a_rotated_file(spawn, tmp_path):
    show = tmp_path / "show.toml"
    show.write_text('[bus]\nmulticast = false\nlisten = ["tcp/127.0.0.1:0"]\n\n'
                    '[log]\nfile = "logs/ignored.log"\nmax_mb = 0.0005\nkeep = 40\n\n'
                    '[nodes.pepper]\nadapter = "sim"\nrate_hz = 20\n')
    log = tmp_path / "elsewhere" / "show.log"  # --log-file wins over [log] file; [log] still sizes it
    run = spawn(SONIBUS, "run", str(show), "--log-file", str(log), collect=True)
    wait_for(lambda: any("sonibus: bus: " in line for line in run.lines), 20, "the run's start")
    code, _, err = run.stop()
    assert code == 130, err
    assert run.lines[0] == f"sonibus: logging to {log} (rotated at 0.0005 MB, 40 kept)"
    assert not (tmp_path / "logs").exists()
    files = sorted(p.name for p in log.parent.iterdir())
    # 500 bytes a file: the start alone rotates it; 40 kept hold all it says (3 did not: the run says more
    # at its start than it did, and the first lines were gone) — how many are kept is the test above's
    assert "show.log.1" in files and len(files) <= 41, files
    text = "".join((log.parent / name).read_text() for name in reversed(files))
    for said in filter(None, run.lines):  # what it said on stdout is in the file too, with the time
        assert re.search(rf"^\S+ \S+ INFO sonibus.run: {re.escape(said)}$", text, re.M), said
    assert re.search(r"INFO sonibus.bus.adapter: pepper: stopping; ", text)  # (INFO: the nodes' own lines)
    assert "INFO" not in err  # stderr keeps its level (warnings)


def test_a_log_file_that_cannot_be_written_is_one_line_and_nothing_starts(tmp_path):
    (tmp_path / "a-file").write_text("")
    show = tmp_path / "show.toml"
    show.write_text('[log]\nfile = "a-file/show.log"\n\n[nodes.pepper]\nadapter = "sim"\n')
    env = Environment(stdout=io.StringIO(), stderr=io.StringIO())
    assert main(["run", str(show), "--no-multicast"], env) == 2
    assert env.stderr.getvalue() == (f"sonibus: error: log file {tmp_path}/a-file/show.log: File exists: "
                                     f"{tmp_path}/a-file — give a file in a folder this user can write ([log] file, "
                                     f"or --log-file)\n")
    assert env.stdout.getvalue() == ""
