"""``sonibus service`` writes a systemd unit that systemd itself accepts (``systemd-analyze
verify``, Debian's systemd: it parses units without systemd running as PID 1)."""

from __future__ import annotations

import io
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from sonibus.bus.cli import Environment, main
from sonibus.bus.cli import service as service_module

from .conftest import require_tool

SHOW = '[bus]\nmulticast = false\n\n[nodes.pepper]\nadapter = "sim"\nhost = "stage"\n\n' \
       '[nodes.sound]\nadapter = "osc"\nhost = "sound-pc"\n'


def cli(*args: str) -> tuple[int, str, str]:
    env = Environment(stdout=io.StringIO(), stderr=io.StringIO())
    code = main(list(args), env)
    return code, env.stdout.getvalue(), env.stderr.getvalue()


def verify(unit: Path) -> subprocess.CompletedProcess[str]:
    tool = require_tool("systemd-analyze", "systemd")
    return subprocess.run([tool, "verify", "--man=no", str(unit)], capture_output=True, text=True, timeout=60)


def test_the_unit_runs_one_hosts_nodes_supervised_and_systemd_accepts_it(tmp_path):
    show = tmp_path / "museum.toml"
    show.write_text(SHOW)
    code, out, err = cli("service", str(show), "--host", "stage", "--user", "root", "-o", str(tmp_path))
    assert code == 0, err
    unit = tmp_path / "sonibus-museum-stage.service"
    text = unit.read_text()
    settings = dict(line.split("=", 1) for line in text.splitlines() if "=" in line and not line.startswith("#"))
    assert settings["ExecStart"] == f"{Path(sys.prefix) / 'bin' / 'sonibus'} run {show} --host stage"
    assert settings["WorkingDirectory"] == str(tmp_path) and settings["User"] == "root"
    assert (settings["Type"], settings["Restart"], settings["WatchdogSec"]) == ("notify", "always", "30")
    assert settings["StartLimitIntervalSec"] == "0" and settings["SuccessExitStatus"] == "130"
    assert "StandardOutput" not in settings  # stdout and stderr go to the journal, systemd's default
    assert settings["Description"] == "sonibus show museum.toml on host stage (pepper)"
    assert out.splitlines()[0] == (f"wrote {unit}: museum.toml's nodes of host 'stage' (pepper) as user 'root', "
                                   f"restarted always, watchdog 30 s")
    assert "sudo systemctl enable --now sonibus-museum-stage" in out and "journalctl -u sonibus-museum-stage" in out
    checked = verify(unit)
    assert (checked.returncode, checked.stderr, checked.stdout) == (0, "", ""), checked.stderr


def test_paths_with_spaces_percent_and_dollar_reach_systemd_as_they_are(tmp_path, monkeypatch):
    """systemd reads ExecStart= with its own quoting, specifiers (%) and variables ($):
    ``verify`` checks that the command it parsed out of the line is executable."""
    odd = tmp_path / "my show 100% $HOME"
    odd.mkdir()
    (odd / "sonibus").symlink_to(Path(sys.prefix) / "bin" / "sonibus")
    monkeypatch.setattr(service_module, "_sonibus", lambda: odd / "sonibus")
    (odd / "the show.toml").write_text(SHOW)
    code, _, err = cli("service", str(odd / "the show.toml"), "--host", "stage", "--user", "root", "-o", str(odd))
    assert code == 0, err
    unit = odd / "sonibus-the-show-stage.service"
    odd_in_unit = str(odd).replace("%", "%%")
    assert f'ExecStart="{odd_in_unit}/sonibus" run "{odd_in_unit.replace("$", "$$")}/the show.toml"' in unit.read_text()
    checked = verify(unit)
    assert (checked.returncode, checked.stderr) == (0, ""), checked.stderr
    broken = unit.read_text().replace('ExecStart="', "ExecStart=")  # unquoted, its first word is not the command
    unit.write_text(broken)
    assert verify(unit).returncode != 0


@pytest.mark.parametrize(("args", "error"), [
    (("--host", "nobody-here"), "no node for host 'nobody-here' — hosts: sound-pc, stage; use --host NAME"),
    (("--host", "stage", "--user", "no-such-user-x"),
     "--user 'no-such-user-x': no such user on this machine — give the account that runs the show"),
    (("--host", "stage", "--watchdog-s", "0"), "--watchdog-s 0 / --restart-s 2: give a watchdog of 1 s or more"),
])
def test_a_unit_that_could_not_run_is_not_written(tmp_path, args, error):
    show = tmp_path / "museum.toml"
    show.write_text(SHOW)
    code, out, err = cli("service", str(show), *args, "-o", str(tmp_path))
    assert code == 2 and out == "" and error in err and err.count("\n") == 1, err
    assert not list(tmp_path.glob("*.service"))


def test_the_unit_can_be_printed_instead(tmp_path):
    show = tmp_path / "museum.toml"
    show.write_text(SHOW)
    code, out, _ = cli("service", str(show), "--host", "sound-pc", "--user", "root", "-o", "-", "--watchdog-s", "12")
    assert code == 0 and out.startswith("# Written by `sonibus service`") and "\nWatchdogSec=12\n" in out
    assert "Description=sonibus show museum.toml on host sound-pc (sound)" in out


# -- issue 33, item 7: no value from outside writes a directive of its own ----------------------------

ANY_HOST = '[bus]\nmulticast = false\n\n[nodes.pepper]\nadapter = "sim"\n'   # a node for whichever host runs it
INJECTED = "\n[Service]\nExecStartPre=true"                                    # what would be a directive of its own


def hostile(tmp_path: Path, case: str) -> tuple[Path, list[str]]:
    """The show's file and the command's arguments for one way of smuggling a directive in."""
    folder, name, node, host = tmp_path, "museum.toml", "pepper", "stage"
    if case == "node name \\n":
        node = f"pepper{INJECTED}"
    elif case == "node name \\r":
        node = f"pepper{INJECTED}".replace("\n", "\r")
    elif case == "--host":
        host += INJECTED
    elif case == "file name":
        name = f"museum{INJECTED}.toml"
    elif case == "folder":
        folder = tmp_path / f"shows{INJECTED}"
    elif case == "folder ending with a backslash":  # WorkingDirectory= would go on over User=
        folder = tmp_path / "shows\\"
    folder.mkdir(exist_ok=True)
    show = folder / name
    show.write_text(ANY_HOST.replace("[nodes.pepper]", f"[nodes.{json.dumps(node)}]"))
    return show, ["--host", host]


@pytest.mark.parametrize(("case", "error"), [
    ("node name \\n", r"node name 'pepper\n[Service]\nExecStartPre=true' must be non-empty without"),
    ("node name \\r", r"node name 'pepper\r[Service]\rExecStartPre=true' must be non-empty without"),
    ("--host", r"--host 'stage\n[Service]\nExecStartPre=true' holds control characters (\n, \n) that a systemd "
               "unit cannot carry — give the machine's name"),
    ("file name", r"museum\n[Service]\nExecStartPre=true.toml' holds control characters (\n, \n)"),
    ("folder", r"[Service]\nExecStartPre=true/museum.toml' holds control characters (\n, \n)"),
    ("folder ending with a backslash", "ends with a space or a backslash, which a unit's WorkingDirectory= "
                                       "cannot carry — rename the folder"),
])
def test_a_name_host_or_path_that_would_write_a_directive_is_refused_and_no_unit_written(tmp_path, case, error):
    show, args = hostile(tmp_path, case)
    code, out, err = cli("service", str(show), *args, "--user", "root", "-o", str(tmp_path))
    assert (code, out) == (2, ""), out
    assert error in err and err.count("\n") == 1 and err.startswith("sonibus: error: "), err
    assert not list(tmp_path.rglob("*.service"))


def test_odd_but_printable_node_names_reach_the_description_as_they_are(tmp_path):
    """What a node name may hold (quotes, backslash, ';', '=', '%', brackets) stays a literal of one line."""
    odd = 'a"b\\c;d=e%n[Service]'
    show = tmp_path / "museum.toml"
    show.write_text(ANY_HOST.replace("[nodes.pepper]", f"[nodes.{json.dumps(odd)}]"))
    code, _, err = cli("service", str(show), "--host", "stage", "--user", "root", "-o", str(tmp_path))
    assert code == 0, err
    unit = tmp_path / "sonibus-museum-stage.service"
    lines = unit.read_text().splitlines()
    assert 'Description=sonibus show museum.toml on host stage (a"b\\c;d=e%%n[Service])' in lines
    assert sum(line.startswith("[") for line in lines) == 3  # [Unit], [Service], [Install]: no more
    assert verify(unit).returncode == 0


def test_a_unit_systemd_refuses_is_not_written(tmp_path, monkeypatch):
    """``systemd-analyze verify`` runs before the unit is written: a command that cannot run stops it."""
    require_tool("systemd-analyze", "systemd")
    not_executable = tmp_path / "sonibus"
    not_executable.write_text("")
    monkeypatch.setattr(service_module, "_sonibus", lambda: not_executable)
    show = tmp_path / "museum.toml"
    show.write_text(SHOW)
    code, out, err = cli("service", str(show), "--host", "stage", "--user", "root", "-o", str(tmp_path))
    # (sonibus's own check of the user's rights says it first: issue 37)
    assert (code, out) == (2, "") and err.count("\n") == 1, err
    assert f"--user 'root' cannot run ExecStart {not_executable} (mode 644, owner root)" in err
    monkeypatch.setattr(service_module.access, "refusals", lambda user, wanted: [])  # (systemd's check behind it)
    code, out, err = cli("service", str(show), "--host", "stage", "--user", "root", "-o", str(tmp_path))
    assert (code, out) == (2, "") and err.count("\n") == 1, err
    assert (f"systemd refuses the unit, not written: sonibus-museum-stage.service: Command {not_executable} is not "
            f"executable") in err
    assert not list(tmp_path.glob("*.service"))


def test_without_systemd_analyze_the_unit_is_written_and_said_unchecked(tmp_path, monkeypatch):
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))  # (a machine without systemd's tools)
    show = tmp_path / "museum.toml"
    show.write_text(SHOW)
    code, out, err = cli("service", str(show), "--host", "stage", "--user", "root", "-o", str(tmp_path))
    assert code == 0 and (tmp_path / "sonibus-museum-stage.service").is_file(), err
    assert "not checked by systemd: no systemd-analyze here (Debian: apt install systemd)" in err + out


def test_a_user_who_cannot_read_the_file_or_write_the_recordings_gets_no_unit(request, monkeypatch):
    """Issue 37, item 9: only the user's existence was checked; a unit whose user cannot read its
    file, or write the recordings' folder, failed at every restart. Checked by owner, group and mode."""
    tmp_path = Path(tempfile.mkdtemp(prefix="sb-service-", dir="/tmp"))  # (pytest's own folder is root's alone)
    request.addfinalizer(lambda: shutil.rmtree(tmp_path, ignore_errors=True))
    tmp_path.chmod(0o755)
    runnable = tmp_path / "sonibus"  # (where this checkout's sonibus is, 'nobody' may not enter: not tested here)
    runnable.write_text("#!/bin/sh\n")
    runnable.chmod(0o755)
    monkeypatch.setattr(service_module, "_sonibus", lambda: runnable)
    show = tmp_path / "museum.toml"
    show.write_text(SHOW + '\n[nodes.rec]\nadapter = "recorder"\nhost = "stage"\npath = "recs/show-{time}.mcap"\n')
    out = tmp_path / "units"
    out.mkdir()
    show.chmod(0o600)  # root's alone: 'nobody' cannot read it
    code, _, err = cli("service", str(show), "--host", "stage", "--user", "nobody", "-o", str(out))
    assert code != 0 and f"--user 'nobody' cannot read the installation file {show} (mode 600, owner root)" in err
    assert len(err.strip().splitlines()) == 1 and not list(out.iterdir()), err
    show.chmod(0o644)  # readable; the recordings' folder is to be made in tmp_path (root's, 755)
    code, _, err = cli("service", str(show), "--host", "stage", "--user", "nobody", "-o", str(out))
    assert code != 0 and f"cannot write a folder the show writes {tmp_path / 'recs'} (to be made in {tmp_path}" in err
    (tmp_path / "recs").mkdir(mode=0o777)
    (tmp_path / "recs").chmod(0o777)
    code, _, err = cli("service", str(show), "--host", "stage", "--user", "nobody", "-o", str(out))
    assert code == 0, err
