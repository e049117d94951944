"""A behavior played on a clock of its own, with no wall time and no bus: the
frames a recording of the simulator playing it would hold, the same every time
(golden values in tests, plots in docs).

>>> from sonibus.bus import load_model
>>> frames = list(play(load_model("pepper"), "animations/Stand/Gestures/Hey_1", 50.0, 4.5))
>>> len(frames), frames[0][0], round(frames[-1][0], 2)
(225, 0.0, 4.48)
"""

from __future__ import annotations

from collections.abc import Iterator

from sonibus.bus.robot import RobotModel

from .behaviors import LIBRARY, Playback
from .motion import Body


def play(model: RobotModel, behavior: str, rate_hz: float, seconds: float, start_s: float = 0.5,
         posture: str = "StandInit") -> Iterator[tuple[float, list[float]]]:
    """``(t, positions in model.joint_names order)`` every 1/``rate_hz`` s for ``seconds``, the
    robot standing in ``posture`` and starting ``behavior`` at ``start_s``, as the simulator's
    engine moves it (targets from the playback, then a step under the joints' speed limits)."""
    body = Body(model, model.posture(posture) if posture in model.postures else {})
    playback: Playback | None = None
    dt = 1.0 / rate_hz
    for k in range(round(seconds * rate_hz)):
        t = k * dt
        if playback is None and k == round(start_s * rate_hz):
            playback = Playback(LIBRARY[behavior], body.pose())
        if playback is not None:
            targets, _ = playback.targets(t - start_s)
            body.set_targets(targets, 1.0)
        body.step(dt)
        yield t, list(body.positions)
