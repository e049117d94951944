"""Simulated Pepper and NAO (adapter ``sim``): ``SimRobot`` with ``SimConfig``."""

from .adapter import SimConfig, SimRobot

__all__ = ["SimConfig", "SimRobot"]
