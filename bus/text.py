"""Text from the bus or a client, made safe to show: a robot, node or key name, an
event's text, what a WebSocket client sent. Control characters are shown as '�':
in a terminal an escape sequence would clear the screen or retitle it, and a
newline would forge a log line or break a row.

>>> printable("A\\x1b[2J\\nB")
'A�[2J�B'
"""

from __future__ import annotations

import logging
import re

__all__ = ["PrintableFormatter", "printable"]

CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f]")  # what a terminal takes as commands (ESC sequences, newlines)


def printable(text: str) -> str:
    """``text`` with its control characters shown as '�'."""
    return CONTROL.sub("\ufffd", text)


class PrintableFormatter(logging.Formatter):
    """A log line's message made printable (its traceback, if any, is left as it is):
    every warning may quote a name that came off the bus."""

    def formatMessage(self, record: logging.LogRecord) -> str:
        record.message = printable(record.message)
        return super().formatMessage(record)
