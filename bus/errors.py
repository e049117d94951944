"""Exceptions of sonibus. Every one carries a message fit for one line."""

from __future__ import annotations

import unicodedata


class SonibusError(Exception):
    """Base of every error sonibus raises on purpose."""


class ConfigError(SonibusError):
    """A configuration file or option is wrong; the message names where."""


class AdapterError(SonibusError):
    """An adapter cannot be found, loaded or started."""


class NodeFailed(SonibusError):
    """A node of a running installation failed (a worker died); the message names it."""


class OwnershipError(SonibusError):
    """A robot already has an owner on the bus."""


class CommandError(SonibusError):
    """A command was refused or failed; ``code`` is machine-readable."""

    def __init__(self, code: str, message: str) -> None:
        super().__init__(message)
        self.code = code
        self.message = message

    def to_payload(self) -> dict:
        return {"code": self.code, "message": self.message}


class RobotNotFound(CommandError):
    """No node on the bus owns the robot a command was sent to."""

    def __init__(self, robot: str) -> None:
        super().__init__("robot_not_found", f"robot '{robot}' not found: no node on the bus owns it")
        self.robot = robot


def controls(text: str) -> list[str]:
    """The control characters in ``text`` (``\\n``, ``\\r``, ``\\x1b``...; an undecodable
    byte of a file name too), written as escapes; [] when it has none.

    >>> controls("stage"), controls("a\\n[Service]\\r")
    ([], ['\\\\n', '\\\\r'])
    """
    return [_escape(c) for c in text if unicodedata.category(c) in ("Cc", "Cs")]


def visible(text: str) -> str:
    """``text`` with its control characters written as escapes, for a message of one line.

    >>> print(visible("a\\n[Service]"))
    a\\n[Service]
    """
    return "".join(_escape(c) if unicodedata.category(c) in ("Cc", "Cs") else c for c in text)


def _escape(char: str) -> str:
    return char.encode("unicode_escape", "backslashreplace").decode("ascii")
