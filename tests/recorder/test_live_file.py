"""A file being written is told from a torn one, also after a crash: the recorder
holds the file's lock while it writes, and the kernel drops that lock with the
process however it ends (no sidecar that a crash would leave behind)."""

from __future__ import annotations

import json

from ..conftest import SONIBUS, run_cli, wait_for


def test_info_on_a_file_being_written_says_so_and_a_killed_recorder_leaves_a_torn_one(net, tmp_path, spawn):
    path = tmp_path / "live.mcap"
    recording = spawn(SONIBUS, "record", str(path), *net.cli_args())
    net.sim("pepper", rate_hz=50, body_sound=False)
    wait_for(lambda: path.exists() and path.stat().st_size > 5_000, timeout=20, what="a chunk on disk")

    info = run_cli("info", str(path))
    assert info.returncode == 0, info.stderr
    assert info.stdout.startswith(f"{path}: being written, by record on "), info.stdout
    assert "MB so far" in info.stdout and "truncated" not in info.stdout + info.stderr
    facts = json.loads(run_cli("info", str(path), "--json").stdout)
    assert facts["being_written"] is True and facts["recorder"]["node"] == "record"
    export = run_cli("export", str(path), "--csv", str(tmp_path / "csv"))
    assert export.returncode == 1 and f"{path} is being written: a recorder that is running holds it" \
        in export.stderr, export.stderr

    recording.kill()  # SIGKILL: no summary, and the lock goes with the process
    info = run_cli("info", str(path))
    assert info.returncode == 1 and f"{path} is truncated: it was not closed cleanly" in info.stderr, info.stderr
