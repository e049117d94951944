"""Mappings from movement to sound (adapter ``map``).

    [nodes.sound]
    adapter = "map"
    [nodes.sound.maps.cutoff]
    source = "pepper/derived/hand/R.z"
    to = [200, 2000]
    unit = "Hz"
    curve = "exp"
    smooth_ms = 80

Each map's output goes out on ``<node>/derived/map/<map>`` (``sound/derived/map/cutoff``),
described with its unit and range on ``<node>/info/derived``. The maps are edited while
they run by requests on ``<node>/maps/<verb>`` (``edit.py``: the operator page's mappings
panel, ``sonibus map``), and saved back into the installation file (``save.py``).
See docs/mapping.md.
"""

from .config import MapConfig, MapSpec
from .node import MapNode

__all__ = ["MapConfig", "MapNode", "MapSpec"]
