"""OSC sink (adapter ``osc``): ``OscSink`` with ``OscSinkConfig``."""

from .sink import OscSink, OscSinkConfig, parse_target

__all__ = ["OscSink", "OscSinkConfig", "parse_target"]
