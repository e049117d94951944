"""The naoqi adapter's options, as an installation file gives them."""

from __future__ import annotations

import pytest

from sonibus.adapters.naoqi import NaoqiConfig
from sonibus.adapters.naoqi.connection import AuthenticatorFactory, one_line
from sonibus.adapters.naoqi.discover import choose_source
from sonibus.bus import ConfigError, registry
from sonibus.bus.options import from_mapping


def options(**data):
    return from_mapping(NaoqiConfig, data, "show.toml [nodes.pepper]")


@pytest.mark.parametrize(("url", "endpoint"), [
    ("tcp://192.168.1.20:9559", "tcp://192.168.1.20:9559"),
    ("tcp://192.168.1.20", "tcp://192.168.1.20:9559"),
    ("192.168.1.20", "tcp://192.168.1.20:9559"),
    ("pepper.local:9600", "tcp://pepper.local:9600"),
    ("tcps://10.0.0.4", "tcps://10.0.0.4:9503"),
])
def test_urls(url, endpoint):
    password = "secret" if url.startswith("tcps") else ""
    assert options(url=url, password=password).endpoint == endpoint


@pytest.mark.parametrize(("data", "key", "fragment"), [
    ({"url": "http://pepper:9559"}, "url", "tcp://host:9559"),
    ({"url": "tcp://"}, "url", "not a URL"),
    ({"url": "tcps://10.0.0.4:9503"}, "password", "user and password"),
    ({"url": "tcp://10.0.0.4", "password": "nao"}, "password", "tcps://"),
    ({"source": "dcm"}, "source", "'almemory'"),
    ({"extra": ["cur", "volts"]}, "extra", "'temp'"),
    ({"extra": ["cur", "cur"]}, "extra", "twice"),
    ({"rate_hz": 0}, "rate_hz", "(0, 1000]"),
    ({"robot": "asimo"}, "model", "known models"),
    ({"retry_max_s": 0}, "retry_max_s", "more than 0"),
    ({"speed": 3}, "speed", "unknown key"),
])
def test_bad_options_name_the_key(data, key, fragment):
    with pytest.raises(ConfigError) as caught:
        options(**data)
    assert f"'{key}'" in str(caught.value) and fragment in str(caught.value)


def test_defaults_and_registration():
    config = options()
    assert (config.rate_hz, config.source, config.extra, config.model_name) == (50.0, "auto", (), "pepper")
    assert options(robot="nao2").model_name == "nao"
    assert registry.load("naoqi").Config is NaoqiConfig


def test_naoqi_2_9_login_data():
    authenticator = AuthenticatorFactory("nao", "secret").newAuthenticator()
    assert authenticator.initialAuthData() == {"user": "nao", "token": "secret"}


def test_source_follows_the_robot():
    assert choose_source("pepper", "2.5.10.7") == "almemory"
    assert choose_source("nao", "2.1.4.13") == "almemory"
    assert choose_source("nao", "2.8.6.23") == "motion"
    assert choose_source("pepper", "2.9.5.172") == "motion"
    assert choose_source("nao", "", "V6") == "motion"
    assert choose_source("nao", "") == "almemory"


def test_remote_errors_fit_on_one_line():
    python_side = "RuntimeError: ALMemory::getData: key not found: X\n\nAt:\n  fake.py(6): boom\n"
    assert one_line(python_side) == "ALMemory::getData: key not found: X"
    assert one_line("\tALBehaviorManager::startBehavior\n\tBehavior not found") == \
        "ALBehaviorManager::startBehavior: Behavior not found"
