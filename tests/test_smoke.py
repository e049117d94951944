from sonibus.bus import keys, send_command

from .conftest import wait_for


def test_sim_streams_and_answers(net):
    net.sim("pepper", rate_hz=50)
    listener = net.bus("listener")
    _, queue = listener.subscribe(keys.joints("pepper"))
    wait_for(lambda: len(queue) > 17, what="joint samples")
    assert send_command(listener, "pepper", "say", {"text": "hello"})["duration"] > 0
