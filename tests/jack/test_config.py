"""The jack adapter's options: a wrong one is one line naming its key, before anything runs."""

from __future__ import annotations

import pytest

from sonibus.adapters.jack import JackConfig
from sonibus.bus.errors import ConfigError
from sonibus.bus.options import from_mapping

WHERE = "show.toml [nodes.jack]"


@pytest.mark.parametrize(("options", "key", "says"), [
    ({"inputs": 9}, "inputs", "9 must be in 0..8"),
    ({"inputs": 0}, "inputs", "is 0 while to_robot is true"),
    ({"outputs": ["front", "front"]}, "outputs", "port 'front' is named twice"),
    ({"outputs": ["pd:in"]}, "outputs", "without ':'"),
    ({"inputs": True}, "inputs", "is not an integer or a list of strings"),
    ({"connect_inputs": ["a:1", "a:2", "a:3"]}, "connect_inputs", "3 ports for 2 inputs"),
    ({"to_robot": False, "from_robot": False}, "to_robot", "the node would do nothing"),
    ({"chunk_ms": 250}, "chunk_ms", "must be in 1..100"),
    ({"target_ms": 0}, "target_ms", "more than 0"),
    ({"client_name": "a:b"}, "client_name", "without ':'"),
    ({"robot": "pep per"}, "robot", "without '/'"),
    ({"speakers": 2}, "speakers", "unknown key 'speakers'"),
])
def test_a_wrong_option_is_one_line_naming_its_key(options, key, says):
    with pytest.raises(ConfigError) as error:
        from_mapping(JackConfig, options, WHERE)
    message = str(error.value)
    assert message.startswith(WHERE) and f"'{key}'" in message and says in message, message
    assert len(message.splitlines()) == 1


def test_ports_are_counted_or_named_and_a_side_can_be_left_out():
    config = from_mapping(JackConfig, {"inputs": ["left", "right"], "outputs": 4, "to_robot": True}, WHERE)
    assert config.input_names == ("left", "right")
    assert config.output_names == ("mic_1", "mic_2", "mic_3", "mic_4")
    assert from_mapping(JackConfig, {"outputs": 0, "from_robot": False}, WHERE).output_names == ()
