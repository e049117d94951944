"""Real Pepper and NAO over NAOqi (adapter ``naoqi``): ``NaoqiRobot`` with ``NaoqiConfig``.

Needs libqi (``pip install 'sonibus[naoqi]'``); see docs/naoqi.md."""

from .adapter import NaoqiRobot
from .config import NaoqiConfig

__all__ = ["NaoqiConfig", "NaoqiRobot"]
