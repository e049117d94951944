"""Foxglove (foxglove.dev) for sonibus: recordings that open well in it, and the
bus live in it (docs/foxglove.md).

- ``convert``: events as ``foxglove.Log``, frames as ``foxglove.FrameTransforms`` (pure).
- ``views``: the channels made for Foxglove beside the bus's keys (``<robot>/frame``,
  ``/log``, ``/tf``, ``/info/derived``), shared by the recorder and the live adapter.
- ``server``: the ``foxglove`` adapter, ``FoxgloveServer`` (needs the ``foxglove``
  extra, foxglove-sdk; nothing else here does, so it is not imported here).
"""

__all__: list[str] = []
