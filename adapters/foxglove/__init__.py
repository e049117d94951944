"""Foxglove: recordings that open well in Foxglove, and a live Foxglove WebSocket server."""
