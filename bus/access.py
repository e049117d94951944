"""Whether another user may run, read or write a path, by its owner, group and mode bits
(``sonibus service`` checks the show's account before it writes a unit for it: a unit
whose user cannot read its file fails at every restart, in a log nobody reads).

ACLs and mandatory access control (AppArmor, SELinux) are not looked at: the mode bits
are what a show's folder usually relies on.

>>> import getpass, tempfile
>>> folder = tempfile.mkdtemp()
>>> refusals(getpass.getuser(), [(Path(folder), "write", "a folder the show writes")])
[]
"""

from __future__ import annotations

import os
import pwd
import stat
from collections.abc import Iterable
from pathlib import Path

BITS = {"read": 4, "write": 2, "run": 1}


def refusals(user: str, wanted: Iterable[tuple[Path, str, str]]) -> list[str]:
    """What ``user`` cannot do of ``wanted`` (path, ``read`` | ``write`` | ``run``, what the path is),
    one phrase each: ``"read the installation file /srv/show.toml (mode 600, owner root)"``. A folder
    to write that does not exist yet counts as its nearest existing parent (it will be made there)."""
    account = pwd.getpwnam(user)
    groups = set(os.getgrouplist(user, account.pw_gid))
    out = []
    for path, how, what in wanted:
        path = path.absolute()
        target = path
        if how == "write":
            while not target.exists() and target != target.parent:
                target = target.parent
        blocked = _blocked(account.pw_uid, groups, target, how)
        if blocked is not None:
            if blocked != target:
                at = f" (its folder {blocked}{_described(blocked)} cannot be entered)"
            elif target != path:
                at = f" (to be made in {target}{_described(target)})"
            else:
                at = _described(target)
            out.append(f"{how} {what} {path}{at}")
    return out


def _blocked(uid: int, groups: set[int], path: Path, how: str) -> Path | None:
    """The first path on the way that refuses: a folder above that cannot be entered, or ``path`` itself."""
    for folder in reversed(path.parents):
        if not _allows(uid, groups, folder, 1):
            return folder
    want = BITS[how] | (1 if how == "write" and path.is_dir() else 0)  # (writing in a folder needs x too)
    return None if _allows(uid, groups, path, want) else path


def _allows(uid: int, groups: set[int], path: Path, want: int) -> bool:
    try:
        info = path.stat()
    except OSError:
        return False
    if uid == 0:  # root reads and writes everything; runs what anyone may run
        return want != 1 or bool(info.st_mode & 0o111) or stat.S_ISDIR(info.st_mode)
    shift = 6 if info.st_uid == uid else 3 if info.st_gid in groups else 0
    return (info.st_mode >> shift) & want == want


def _described(path: Path) -> str:
    try:
        info = path.stat()
        owner = pwd.getpwuid(info.st_uid).pw_name
    except (OSError, KeyError):
        return ""
    return f" (mode {stat.S_IMODE(info.st_mode):o}, owner {owner})"
