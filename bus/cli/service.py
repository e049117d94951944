"""``sonibus service``: a systemd unit that keeps one machine's part of a show running.

    sonibus service museum.toml --host stage --user show
    # wrote ./sonibus-museum-stage.service, then the steps to install, enable and check it

The unit runs ``sonibus run FILE --host NAME`` from this virtualenv, as ``--user``,
in the file's folder; systemd restarts it whenever it ends (a node that failed, a
crash) and, through its watchdog, when it stops saying that every node is healthy
(``bus/watchdog.py``). Its output goes to the journal (``journalctl -u UNIT``).

Every value written into the unit is a literal there, by systemd's rules
(systemd.syntax(7), systemd.service(5) "Command lines"): ``%`` doubled (specifiers),
``$`` doubled in arguments (variables), a word with spaces, quotes, ``\\`` or ``;``
double-quoted with ``\\`` and ``"`` escaped. What a unit cannot carry at all is
refused in one line, nothing written: a control character in a node's name (refused
by ``bus/keys.check_name`` when the file is read), the host, the user, the file's path
or the sonibus command (a newline there would start a directive of its own), and a
folder ending with a space or a backslash (``WorkingDirectory=`` has no quoting: the
line would be trimmed, or continued on the next one). The unit is then checked with
``systemd-analyze verify`` where it exists: one systemd would refuse is not written.
"""

from __future__ import annotations

import argparse
import getpass
import os
import pwd
import re
import shutil
import socket
import subprocess
import sys
import tempfile
from importlib.metadata import version
from pathlib import Path

from .. import access, config, runner
from ..errors import ConfigError, controls, visible
from .api import Command, Environment, Exit

WATCHDOG_S = 30.0  # a hung node is found within adapter.HANG_S, then systemd waits this long for a ping
RESTART_S = 2.0
START_S = 60       # every node's start (the wait for the bus is extended by the run itself: bus/watchdog.py)
VERIFY_S = 30.0    # how long `systemd-analyze verify` may take (it takes a few ms)


def _arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("config", metavar="CONFIG.toml")
    p.add_argument("--host", help="the machine whose nodes it runs, as `sonibus run --host` (default: this one)")
    p.add_argument("--user", help="who runs the show (default: whoever runs this command, sudo's caller under sudo)")
    p.add_argument("-o", "--output", metavar="FOLDER", default=".",
                   help="where to write the unit (default: here; '-' prints it instead)")
    p.add_argument("--watchdog-s", type=float, default=WATCHDOG_S, metavar="S",
                   help=f"restart it when no node-healthy ping came for this long (default {WATCHDOG_S:g})")
    p.add_argument("--restart-s", type=float, default=RESTART_S, metavar="S",
                   help=f"wait before a restart (default {RESTART_S:g})")


def _service(args: argparse.Namespace, env: Environment) -> Exit:
    path = Path(args.config).absolute()
    _plain("the file's path", str(path), "rename the file or its folder")
    host = args.host or socket.gethostname()
    _plain("--host", host, "give the machine's name, as `hostname` prints it")
    installation = config.load(path)
    adapters = runner.build(installation, None, host)  # (every error now, not at each restart)
    nodes = [a.name for a in adapters]
    if not args.watchdog_s >= 1 or not args.restart_s >= 0:
        raise ConfigError(f"--watchdog-s {args.watchdog_s:g} / --restart-s {args.restart_s:g}: give a watchdog of "
                          f"1 s or more and a restart delay of 0 or more, e.g. --watchdog-s {WATCHDOG_S:g}")
    user = args.user or os.environ.get("SUDO_USER") or getpass.getuser()
    _plain("--user", user, "give the account that runs the show")
    try:
        pwd.getpwnam(user)
    except KeyError:
        raise ConfigError(f"--user '{user}': no such user on this machine — give the account that runs the "
                          f"show (`id NAME` checks one)") from None
    folders = [folder for a in adapters for folder in a.writes()]
    if installation.log.file:
        folders.append(str(Path(installation.log.file).parent))
    refused = access.refusals(user, [(_sonibus(), "run", "ExecStart"), (path, "read", "the installation file"),
                                     *((Path(f), "write", "a folder the show writes") for f in folders)])
    if refused:
        raise ConfigError(f"--user '{user}' cannot {refused[0]} — fix its rights, or give another --user")
    name = unit_name(path, host)
    text = unit(path, host, user, nodes, args.watchdog_s, args.restart_s)
    written = Path("-") if args.output == "-" else Path(args.output).absolute() / f"{name}.service"
    _plain("--output", str(written.parent), "give a folder without them")
    checked = verify(text, name, written)
    if checked:
        env.hint(checked)
    if args.output == "-":
        env.stdout.write(text)
        return Exit.OK
    try:
        written.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"cannot write {visible(str(written))}: {exc.strerror or exc} — give a folder you can "
                          f"write (--output)") from None
    env.say(f"wrote {written}: {path.name}'s nodes of host '{host}' ({', '.join(nodes)}) as user '{user}', "
            f"restarted always, watchdog {args.watchdog_s:g} s")
    if user == "root":
        env.hint("it runs as root: give --user NAME of the show's account (in group audio for JACK or MIDI)")
    for line in steps(written, name, path):
        env.say(line)
    return Exit.OK


def unit_name(config_path: Path, host: str) -> str:
    """``sonibus-<file>-<host>``, in the characters a unit name may have."""
    return re.sub(r"[^A-Za-z0-9:_.-]", "-", f"sonibus-{config_path.stem}-{host}")


def verify(text: str, name: str, target: Path) -> str:
    """Check the unit with ``systemd-analyze verify`` (written to a folder of its own first);
    ``ConfigError`` with systemd's first complaint if it refuses it. What to tell the user
    when it could not be checked, else ""."""
    tool = shutil.which("systemd-analyze")
    if tool is None:
        return "not checked by systemd: no systemd-analyze here (Debian: apt install systemd)"
    with tempfile.TemporaryDirectory(prefix="sonibus-service-") as folder:
        draft = Path(folder) / f"{name}.service"
        draft.write_text(text, encoding="utf-8")
        try:
            done = subprocess.run([tool, "verify", "--man=no", str(draft)], capture_output=True, text=True,
                                  timeout=VERIFY_S, check=False)
        except subprocess.TimeoutExpired:
            return f"not checked by systemd: systemd-analyze verify took over {VERIFY_S:g} s"
    if done.returncode == 0:
        return ""
    said = [line.strip() for line in (done.stderr + done.stdout).splitlines() if line.strip()]
    first = (said[0] if said else f"exit status {done.returncode}").replace(str(draft), str(target))
    raise ConfigError(f"systemd refuses the unit, not written: {visible(first)} — fix what it names "
                      f"(`systemd-analyze verify FILE` shows all)")


def unit(config_path: Path, host: str, user: str, nodes: list[str], watchdog_s: float, restart_s: float) -> str:
    """The unit's text; ``ConfigError`` for a value a unit cannot carry."""
    command = [str(_sonibus()), "run", str(config_path), "--host", host]
    for what, value in (("the sonibus command", command[0]), ("the file's path", command[2]), ("--host", host),
                        ("--user", user), *(("node name", node) for node in nodes)):
        _plain(what, value, "rename it")
    folder = str(config_path.parent)
    if folder != folder.rstrip(" \t\\"):
        raise ConfigError(f"the file's folder '{folder}' ends with a space or a backslash, which a unit's "
                          f"WorkingDirectory= cannot carry — rename the folder")
    return f"""# Written by `sonibus service` (sonibus {version("sonibus")}): {config_path.name}, host {host}.
# Steps to install, enable and check it: README, "On show day".
[Unit]
Description=sonibus show {_escaped(config_path.name)} on host {_escaped(host)} ({_escaped(', '.join(nodes))})
Wants=network-online.target
After=network-online.target sound.target
# never give up restarting (systemd's default stops after 5 starts in 10 s)
StartLimitIntervalSec=0

[Service]
# READY once every node runs; WATCHDOG pings only while every node is healthy
Type=notify
NotifyAccess=main
WatchdogSec={watchdog_s:g}
Restart=always
RestartSec={restart_s:g}
TimeoutStartSec={START_S}
TimeoutStopSec=10
# sonibus ends a stop by SIGTERM with 130, as after Ctrl-C
SuccessExitStatus=130
# SIGTERM to sonibus only, which stops its nodes (and what they started) in order
KillMode=mixed
ExecStart={' '.join(_argument(a, command=i == 0) for i, a in enumerate(command))}
WorkingDirectory={_escaped(folder)}
User={_escaped(user)}
# $STATE_DIRECTORY: where the run keeps how it ended (bus/restarts.py)
StateDirectory=sonibus
# unbuffered lines to the journal; a watchdog's SIGABRT prints every thread's stack there
Environment=PYTHONUNBUFFERED=1 PYTHONFAULTHANDLER=1
SyslogIdentifier={unit_name(config_path, host)}
# no core file of hundreds of MB per watchdog kill in the show's folder
LimitCORE=0

[Install]
WantedBy=multi-user.target
"""


def steps(written: Path, name: str, config_path: Path) -> list[str]:
    """What to do with the unit, numbered."""
    return [
        "to install, enable and check it:",
        f"  1. sudo install -m 644 {written} /etc/systemd/system/",
        "  2. sudo systemctl daemon-reload",
        f"  3. sudo systemctl enable --now {name}      # starts now and at every boot",
        f"  4. systemctl status {name}      # 'active (running)', Status: 'running <nodes> on <host>'",
        f"  5. journalctl -u {name} -f      # its log: where each node is reached, warnings, restarts",
        f"after editing {config_path.name}: sudo systemctl restart {name}; "
        f"to end the show: sudo systemctl stop {name} (disable --now: also at boot)",
    ]


def _sonibus() -> Path:
    """The ``sonibus`` command of this installation (its virtualenv's, symlinks kept)."""
    here = Path(sys.prefix) / "bin" / "sonibus"
    if here.is_file():
        return here
    found = shutil.which("sonibus")
    if found is None:
        raise ConfigError(f"no sonibus command in {here.parent} nor on PATH — install sonibus in a virtualenv "
                          f"(README, 'Install') and run this command from it")
    return Path(found).absolute()


def _plain(what: str, value: str, fix: str) -> None:
    """``ConfigError`` if ``value`` holds a control character: a newline would end the unit's line there."""
    found = controls(value)
    if found:
        raise ConfigError(f"{what} '{visible(value)}' holds control characters ({', '.join(found)}) that a "
                          f"systemd unit cannot carry — {fix}")


def _escaped(text: str) -> str:
    """``text`` for a unit's value: a ``%`` kept literal (not one of systemd's specifiers)."""
    return text.replace("%", "%%")


def _argument(text: str, command: bool = False) -> str:
    """One word of ``ExecStart=``: ``%`` kept literal, and ``$`` in an argument (systemd
    expands variables there, not in the ``command`` itself); quoted when it has spaces or
    quotes (systemd's rules)."""
    text = _escaped(text) if command else _escaped(text).replace("$", "$$")
    if text and not re.search(r"[\s\"'\\;]", text):
        return text
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


SERVICE = Command("service", "write a systemd unit that runs and supervises one host's nodes", _arguments, _service)
