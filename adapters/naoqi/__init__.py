"""Real Pepper and NAO over NAOqi (adapter ``naoqi``): ``NaoqiRobot`` with ``NaoqiConfig``.

Needs libqi, the ``naoqi`` extra (``pip install -e '.[naoqi]'`` in sonibus's clone); see docs/naoqi.md."""

from .adapter import NaoqiRobot
from .config import NaoqiConfig

__all__ = ["NaoqiConfig", "NaoqiRobot"]
