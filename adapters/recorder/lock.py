"""The lock a recorder holds on the file it writes: how a reader tells a file
still being written from one a crash left torn.

Both end without the MCAP footer. The writer holds an exclusive ``flock`` on
its open file until it has closed it; the kernel drops that lock whenever the
process ends, however it ends (SIGKILL, a crash, a power cut: the lock was
never on disk), so unlike a sidecar file it can never outlive the writer and
make a torn file look live. ``flock`` locks belong to an open file, not to a
process: a reader in the recorder's own process sees the lock too.

Where there is no ``flock`` (Windows) nothing is locked and a live file reads
as a torn one.

>>> import os, tempfile
>>> path = os.path.join(tempfile.mkdtemp(), "live.mcap")
>>> with open(path, "wb") as f:
...     hold(f.fileno()), held(path)
(True, True)
>>> held(path)
False
"""

from __future__ import annotations

import os

try:
    import fcntl
except ImportError:  # (Windows)
    fcntl = None  # type: ignore[assignment]


def hold(fd: int) -> bool:
    """Take the writer's lock on the open file ``fd`` until it is closed; False if
    another open file (another recorder) holds it."""
    if fcntl is None:
        return True
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    return True


def held(path: str) -> bool:
    """Whether a writer holds the lock of ``path`` now (a recorder is writing it)."""
    if fcntl is None:
        return False
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    except OSError:  # a file system without locks
        return False
    finally:
        os.close(fd)  # (and the shared lock with it)
    return False
