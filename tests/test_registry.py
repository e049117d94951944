"""The adapter registry (entry-point group ``sonibus.adapters``) and the adapter lifecycle."""

from __future__ import annotations

import json
import logging

import pytest
from sonibus_testplugin import JsonLinesConfig, JsonLinesSink

from sonibus.adapters.console import ConsoleView
from sonibus.adapters.osc import OscSink
from sonibus.adapters.sim import SimRobot
from sonibus.bus import Adapter, AdapterError, keys, registry

from .conftest import wait_for

BUILT_IN = {"sim": SimRobot, "osc": OscSink, "console": ConsoleView}


def test_available_lists_built_ins_and_the_plugin_without_importing():
    found = registry.available()
    assert {"sim", "osc", "console", "jsonl", "broken"} <= set(found)
    assert found["jsonl"].value == "sonibus_testplugin:JsonLinesSink"
    assert found["sim"].value == "sonibus.adapters.sim:SimRobot"


@pytest.mark.parametrize("name", sorted(BUILT_IN))
def test_load_built_in(name):
    assert registry.load(name) is BUILT_IN[name]


def test_load_plugin_returns_its_class():
    cls = registry.load("jsonl")
    assert cls is JsonLinesSink
    assert issubclass(cls, Adapter)
    assert cls.Config is JsonLinesConfig
    assert registry.summary(cls).startswith("Appends every sample")


def test_load_unknown_lists_installed_adapters():
    with pytest.raises(AdapterError) as caught:
        registry.load("nope")
    message = str(caught.value)
    assert "'nope'" in message
    for name in ("sim", "osc", "console", "jsonl"):
        assert name in message.partition("'nope'")[2], f"{name} not listed: {message}"
    assert "\n" not in message


def test_load_broken_names_it_and_why():
    with pytest.raises(AdapterError) as caught:
        registry.load("broken")
    message = str(caught.value)
    assert "'broken'" in message
    assert "DoesNotExist" in message  # what could not be imported
    assert "\n" not in message


def test_load_all_skips_broken_with_one_warning(caplog):
    caplog.set_level(logging.WARNING, logger="sonibus")
    loaded = registry.load_all()
    assert "broken" not in loaded
    assert {name: loaded[name] for name in BUILT_IN} == BUILT_IN
    assert loaded["jsonl"] is JsonLinesSink
    warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1, [r.getMessage() for r in warnings]
    assert warnings[0].name == "sonibus.bus.registry"
    assert "'broken'" in warnings[0].getMessage()
    assert "skipped" in warnings[0].getMessage()


def test_adapter_lifecycle_start_twice_stop_twice_and_repr(net, tmp_path):
    out = tmp_path / "samples.jsonl"
    sink = JsonLinesSink(JsonLinesConfig(path=str(out), subscribe="pepper/joints/HeadYaw"), name="rec")
    assert repr(sink) == "<JsonLinesSink 'rec' new>"
    net.sim("pepper", rate_hz=50)
    bus = net.bus("rec-host")
    sink.start(bus)
    try:
        assert sink.state == "running"
        assert repr(sink) == "<JsonLinesSink 'rec' running>"
        wait_for(lambda: out.exists() and out.read_text().count("\n") >= 3, what="samples in the file")
        with pytest.raises(RuntimeError, match="running"):
            sink.start(bus)
        assert sink.state == "running"  # the failed second start changed nothing
        assert bus.alive(keys.node_token(bus.host, "rec"))
    finally:
        sink.stop()
    assert sink.state == "stopped"
    assert repr(sink) == "<JsonLinesSink 'rec' stopped>"
    sink.stop()  # a second stop is fine
    assert sink.state == "stopped"
    assert not [t for t in sink._threads if t.is_alive()]
    wait_for(lambda: not bus.alive(keys.node_token(bus.host, "rec")), what="the node's token to go")
    lines = out.read_text().splitlines()
    assert all(json.loads(line)["key"] == "pepper/joints/HeadYaw" for line in lines)
    with pytest.raises(RuntimeError, match="stopped"):
        sink.start(bus)  # a stopped adapter does not come back


def test_stop_before_start_is_fine():
    view = ConsoleView(name="view")
    view.stop()
    view.stop()
    assert view.state == "stopped"
    assert "stopped" in repr(view) and "'view'" in repr(view)


def test_adapter_takes_only_its_own_config(tmp_path):
    with pytest.raises(TypeError, match="JsonLinesConfig"):
        JsonLinesSink(ConsoleView.Config())
