"""A log file that cannot fill the disk: for a show on a machine without systemd's journal.

``[log]`` in the installation file (or ``sonibus run --log-file PATH``) adds a file
beside stderr: every line of the run, with its time, from INFO up (what the run
says on stdout too: its nodes, where they are reached, restarts). When the file
reaches ``max_mb`` it is renamed ``.1`` (the ``.1`` before it ``.2``, ...) and a new
one started; ``keep`` old files are kept, the oldest deleted::

    [log]
    file = "logs/museum.log"     # relative to the installation file
    max_mb = 10                  # per file
    keep = 5                     # old files kept: at most (keep + 1) × max_mb on disk

>>> LogConfig(max_mb=0)
Traceback (most recent call last):
sonibus.bus.errors.ConfigError: key 'max_mb': 0 must be more than 0 (MB per file), e.g. 10
"""

from __future__ import annotations

import logging
import logging.handlers
from dataclasses import dataclass, replace
from pathlib import Path

from .errors import ConfigError
from .options import bad

FORMAT = "%(asctime)s %(levelname)s %(name)s: %(message)s"
LOGGER = "sonibus"  # every module logs under it


@dataclass(frozen=True)
class LogConfig:
    """The ``[log]`` table: ``file`` ("" for none), ``max_mb`` per file, ``keep`` old files."""

    file: str = ""
    max_mb: float = 10.0
    keep: int = 5

    def __post_init__(self) -> None:
        if not self.max_mb > 0:
            raise bad("max_mb", f"{self.max_mb:g} must be more than 0 (MB per file), e.g. 10")
        if self.keep < 1:
            raise bad("keep", f"{self.keep} must be 1 or more (old files kept), e.g. 5")

    def relative_to(self, folder: Path) -> LogConfig:
        """``file`` taken relative to ``folder`` (the installation file's)."""
        if not self.file or Path(self.file).expanduser().is_absolute():
            return replace(self, file=str(Path(self.file).expanduser()) if self.file else "")
        return replace(self, file=str(folder / self.file))


class LogFile:
    """The rotating file of ``config``, attached to sonibus's logger until ``close``."""

    def __init__(self, config: LogConfig) -> None:
        self.path = Path(config.file)
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.handler = logging.handlers.RotatingFileHandler(
                self.path, maxBytes=max(1, int(config.max_mb * 1e6)), backupCount=config.keep, encoding="utf-8")
        except OSError as exc:
            why = f"{exc.strerror}: {exc.filename}" if exc.filename else str(exc)
            raise ConfigError(f"log file {self.path}: {why} — give a file in a folder this user can write "
                              f"([log] file, or --log-file)") from None
        self.handler.setFormatter(logging.Formatter(FORMAT))
        self.handler.setLevel(logging.INFO)
        self._logger = logging.getLogger(LOGGER)
        self._level = self._logger.level
        self._logger.addHandler(self.handler)
        if self._logger.getEffectiveLevel() > logging.INFO:
            self._logger.setLevel(logging.INFO)  # (stderr's handler keeps its own level)

    def note(self, text: str, level: int = logging.INFO) -> None:
        """A line in the file only (what the run also says on stdout or stderr)."""
        self.handler.handle(logging.LogRecord("sonibus.run", level, __file__, 0, text, None, None))

    def close(self) -> None:
        self._logger.removeHandler(self.handler)
        self._logger.setLevel(self._level)
        self.handler.close()
