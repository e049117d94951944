"""The ``jack`` adapter: a robot's speaker and microphones as JACK ports.

    from sonibus.adapters.jack import JackBridge, JackConfig
    bridge = JackBridge(JackConfig(robot="pepper", connect_inputs=("pd:output_1", "pd:output_2")), name="jack")

Needs a running JACK server and libjack (the ``jack`` extra: ``pip install -e '.[jack]'`` in sonibus's clone);
docs/jack.md says how to play Pd into the robot and hear its microphones.
"""

from .adapter import JackBridge
from .config import JackConfig

__all__ = ["JackBridge", "JackConfig"]
