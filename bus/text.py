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
from datetime import datetime

__all__ = ["PrintableFormatter", "printable", "show_state"]

CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f]")  # what a terminal takes as commands (ESC sequences, newlines)


def printable(text: str) -> str:
    """``text`` with its control characters shown as '�'."""
    return CONTROL.sub("\ufffd", text)


def show_state(state: str, later: object = None) -> str:
    """A show's state (``<robot>/events/show``) as a line, its next change in the wall clock of
    the show's own zone (its ISO text's offset), as the pages and ``top`` show it.

    >>> show_state("closed", "2026-11-29T10:00:00+01:00"), show_state("open", None)
    ('closed, opens Sun 10:00', 'open')
    """
    try:
        when = f"{datetime.fromisoformat(str(later)):%a %H:%M}" if later else ""
    except ValueError:
        when = printable(str(later)[:40])
    return f"{state}, {'opens' if state == 'closed' else 'closes'} {when}" if when else state


class PrintableFormatter(logging.Formatter):
    """A log line's message made printable (its traceback, if any, is left as it is):
    every warning may quote a name that came off the bus."""

    def formatMessage(self, record: logging.LogRecord) -> str:
        record.message = printable(record.message)
        return super().formatMessage(record)
