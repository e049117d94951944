"""Whether this run of a show is a restart, how many there were, and how the last run ended.

A supervisor restarts ``sonibus run`` when it ends on its own (a node failed: exit 1),
crashes, or hangs (systemd's watchdog). Under systemd (v248+) ``$NRESTARTS`` counts
the automatic restarts of the service since it was last started by hand. Elsewhere (a
shell loop, runit, a container's restart policy) the count comes from a small state
file per installation file and host: a start after a run that did not end cleanly is
a restart; a start after a clean stop (Ctrl-C, SIGTERM, ``systemctl stop``) starts
the count over. Either way the file tells the new run how the previous one ended,
which systemd does not.

The file lives in ``$STATE_DIRECTORY`` (systemd's ``StateDirectory=``, which
``sonibus service`` sets), else ``$XDG_STATE_HOME/sonibus``, else
``~/.local/state/sonibus``.

>>> import tempfile
>>> folder = tempfile.mkdtemp()
>>> state = RunState.for_run("show.toml", "stage", environ={"STATE_DIRECTORY": folder})
>>> state.begin().count                      # a first start
0
>>> state.end("failed: node 'rec': worker 'write' failed: OSError: disk full")
>>> again = RunState.for_run("show.toml", "stage", environ={"STATE_DIRECTORY": folder}).begin()
>>> again.count, again.previous
(1, "failed: node 'rec': worker 'write' failed: OSError: disk full")
>>> state.end("failed: again")
>>> by_hand = RunState.for_run("show.toml", "stage", environ={"STATE_DIRECTORY": folder}).begin(by_hand=True)
>>> by_hand.count, by_hand.previous                 # from a terminal: not a restart, though it says how it ended
(0, 'failed: again')
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

STOPPED = "stopped"  # how a clean end is written: the next start is not a restart


@dataclass(frozen=True)
class Restart:
    """What a run knows of the runs before it: ``count`` restarts since the show was last
    started by hand (0: this is such a start), how the previous run ended (``previous``,
    "" when unknown or clean), and where the count comes from."""

    count: int = 0
    previous: str = ""
    source: str = ""

    def __str__(self) -> str:
        if not self.count:
            return "first start"
        return (f"restart {self.count} ({self.source}); the previous run "
                + (self.previous if self.previous else "ended without a record"))


class RunState:
    """The state file of one installation file, host and node selection (see the module)."""

    def __init__(self, path: Path | None, environ: Mapping[str, str] | None = None) -> None:
        self.path = path
        self._env = os.environ if environ is None else environ
        self._record: dict[str, Any] = {}

    @classmethod
    def for_run(cls, config: str | Path, host: str, only: Sequence[str] | None = None,
                environ: Mapping[str, str] | None = None) -> RunState:
        """The state of ``sonibus run CONFIG --host HOST [--only ...]``."""
        env = os.environ if environ is None else environ
        resolved = Path(config).resolve()
        key = hashlib.sha1(json.dumps([str(resolved), host, sorted(only or ())]).encode()).hexdigest()[:10]
        return cls(state_folder(env) / f"{resolved.stem}-{host}-{key}.json", env)

    def begin(self, by_hand: bool = False) -> Restart:
        """Read how the previous run ended, and record this one as running. ``by_hand``
        (started from a terminal) starts the count over: a supervisor restarts nothing
        there, and a hand run after a failed one was reported as "restart 2"."""
        previous = self._read()
        ended = previous.get("ended")
        unclean = bool(previous) and ended != STOPPED
        how = ""
        if unclean:
            how = ended or (f"(pid {previous.get('pid', '?')}, started "
                            f"{time.strftime('%Y-%m-%d %H:%M:%S', time.localtime(previous.get('started', 0)))}) "
                            f"ended without a word: killed, crashed, or stopped by a watchdog (see its log)")
        nrestarts = self._env.get("NRESTARTS", "")
        if nrestarts.isdigit():
            count, source = int(nrestarts), "systemd's $NRESTARTS"
        elif by_hand:
            count, source = 0, "started by hand"
        else:
            count, source = (int(previous.get("restarts", 0)) + 1 if unclean else 0), f"counted in {self.path}"
        self._record = {"pid": os.getpid(), "started": time.time(), "restarts": count, "ended": ""}
        self._write()
        return Restart(count, how, source)

    def end(self, how: str) -> None:
        """Record how this run ended: ``STOPPED`` for a clean stop, else why (``failed: ...``)."""
        if self._record:
            self._record["ended"] = how
            self._write()

    def _read(self) -> dict[str, Any]:
        if self.path is None:
            return {}
        try:
            record = json.loads(self.path.read_text(encoding="utf-8"))
        except (FileNotFoundError, NotADirectoryError):  # (a folder that cannot be: said once, when written)
            return {}
        except (OSError, ValueError) as exc:
            log.warning("run state %s unreadable (%s): counting restarts from 0", self.path, exc)
            return {}
        return record if isinstance(record, dict) else {}

    def _write(self) -> None:
        if self.path is None:
            return
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            temporary = self.path.with_name(self.path.name + ".tmp")
            temporary.write_text(json.dumps(self._record), encoding="utf-8")
            os.replace(temporary, self.path)  # whole or not at all, whenever the process is killed
        except OSError as exc:
            log.warning("cannot write the run state %s: %s — restarts are not counted here (set STATE_DIRECTORY "
                        "or XDG_STATE_HOME to a writable folder)", self.path,
                        f"{exc.strerror}: {exc.filename}" if exc.filename else exc)
            self.path = None


def state_folder(environ: Mapping[str, str]) -> Path:
    """Where run states are kept (see the module)."""
    if environ.get("STATE_DIRECTORY"):
        return Path(environ["STATE_DIRECTORY"].split(":")[0])  # (systemd lists several when the unit names several)
    if environ.get("XDG_STATE_HOME"):
        return Path(environ["XDG_STATE_HOME"]) / "sonibus"
    return Path(environ.get("HOME") or Path.home()) / ".local" / "state" / "sonibus"
