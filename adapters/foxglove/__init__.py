"""Foxglove (foxglove.dev) for sonibus: recordings that open well in it, and the
bus live in it (docs/foxglove.md).

- ``convert``: events as ``foxglove.Log``, frames as ``foxglove.FrameTransforms`` (pure).
- ``views``: the channels made for Foxglove beside the bus's keys (``<robot>/frame``,
  ``/log``, ``/tf``, ``/info/derived``), shared by the recorder and the live adapter.
- ``wire``: Foxglove's WebSocket protocol, the server's side (pure); ``hub``: its channels
  and clients on ``bus/web.py``'s server; ``server``: the ``foxglove`` adapter, ``FoxgloveServer``.
"""

__all__: list[str] = []
