"""Audio features as signals (adapter ``hear``): loudness (dB), spectral centroid (Hz)
and onsets of a robot's microphones or of what a JACK input plays into it.

    [nodes.ears]
    adapter = "hear"
    listen = ["pepper/audio/speaker"]

Publishes ``pepper/derived/loudness/speaker``, ``.../centroid/speaker`` and
``.../onset/speaker``, described on ``pepper/info/derived``: a map takes them as
sources (docs/mapping.md, "Audio features").
"""

from .config import HearConfig
from .features import Onsets, centroid_hz, level_db
from .node import Hear

__all__ = ["Hear", "HearConfig", "Onsets", "centroid_hz", "level_db"]
