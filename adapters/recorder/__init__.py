"""Recordings of the bus in MCAP files: record, replay, recover, export, plot."""

from .reading import Message, Recording, RecordingError
from .repair import recover
from .writer import RecordingWriter

__all__ = ["Message", "Recording", "RecordingError", "RecordingWriter", "recover"]
