"""A frame's joints as the Foxglove node serves them, a channel per joint (issue 35: made
from the frame's ``Selected``, no sample ``Incoming`` per joint): the samples each joint's
own key carries (``framing.frame_samples``), extra quantities and all, of the joints the
node's patterns select, in the frame's order."""

from __future__ import annotations

import pytest

from sonibus.adapters.foxglove.views import joint_samples
from sonibus.bus import codec, framing, keys
from sonibus.bus.streams import Selection

NAMES = ["HeadYaw", "LHand", "HeadPitch", "RHand"]


@pytest.mark.parametrize("extra", [{}, {"cmd": [1.0, 2.0, 3.0, 4.0], "effort": [0.5, 0.0, 1, 2]}])
@pytest.mark.parametrize("patterns", [["pepper/joints/*"], ["pepper/joints/Head*", "pepper/joints/RHand"]])
def test_a_frames_joint_samples_are_the_selected_joints_as_their_keys_carry_them(patterns, extra):
    frame = framing.frame(1.5, 7, NAMES, [0.1, 0, 0.3, -2], extra)
    incoming = Selection(patterns).incoming("pepper/frame", codec.encode(frame))
    chosen = {source.name for source in incoming.selected.sources}
    assert joint_samples(incoming) == [(keys.joint("pepper", name), sample)
                                       for name, sample in framing.frame_samples(incoming.message) if name in chosen]
    assert [key for key, _ in joint_samples(incoming)] == [keys.joint("pepper", n) for n in NAMES if n in chosen]
