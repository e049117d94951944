"""OSC for sound tools: the sink ``osc`` (bus → OSC) and the gateway
``osc-gateway`` (OSC → robot commands).

    from sonibus.adapters.osc import OscSink, OscSinkConfig
    sink = OscSink(OscSinkConfig(targets=("127.0.0.1:3005",), profile="pepperosc"), name="sound")
"""

from .config import OscSinkConfig, Target, TargetSettings, parse_target
from .sink import OscSink

__all__ = ["OscSink", "OscSinkConfig", "Target", "TargetSettings", "parse_target"]
