"""A bridge whose broker cannot be reached says so (issue 28): a WARN at the first failed attempt
and then every broker_warn_interval s, naming the robot, the URL and where the URL came from; and
which parameter gave the URL, a leftover private ~broker_url overriding the launch's
~broker_url_param said in a WARN.

Pure (no broker, no ROS): the broker URL points at a closed port on 127.0.0.1, and the client's
clock is a fake one, so the 30 s interval passes without sleeping."""
import logging

import pytest

from coaty_bridge.broker import free_port
from coaty_bridge.client import BridgeConfig, CoatyBridgeClient, FIRST_UNREACHABLE_WARN_AFTER, choose_broker_url


class FakeClock:
    def __init__(self):
        self.now = 1000.0

    def __call__(self):
        return self.now


def unreachable_warnings(caplog):
    return [r.getMessage() for r in caplog.records
            if r.levelno == logging.WARNING and "unreachable" in r.getMessage()]


@pytest.fixture
def closed_url():
    return "mqtt://127.0.0.1:%d" % free_port()   # nothing listens there


def test_unreachable_broker_warns_at_start_and_every_interval(caplog, closed_url, wait_for):
    caplog.set_level(logging.INFO, logger="coaty_bridge")
    clock = FakeClock()
    config = BridgeConfig("robot_4", broker_url=closed_url, broker_warn_interval=30.0, reconnect_min_delay=0.05,
                          reconnect_max_delay=0.2, broker_url_source="parameter /fleet/broker_url")
    client = CoatyBridgeClient(config, lambda u, t: None, clock=clock)
    client.start()
    try:
        # the first attempt is refused at once; no time passes on the client's clock
        wait_for(lambda: unreachable_warnings(caplog), timeout=10, what="the first unreachable warning")
        first = unreachable_warnings(caplog)[0]
        assert "robot_4" in first and closed_url in first and "/fleet/broker_url" in first
        wait_for(lambda: client.counters().get("connect_failures", 0) >= 3, timeout=10, what="more failed attempts")
        assert len(unreachable_warnings(caplog)) == 1, "repeated before the interval: %s" % unreachable_warnings(caplog)
        clock.now += 29.0
        assert not client.check_broker()
        assert len(unreachable_warnings(caplog)) == 1
        clock.now += 1.0
        client.check_broker()          # due now (the watch thread may have said it first, once)
        assert len(unreachable_warnings(caplog)) == 2
        assert "unreachable for 30 s" in unreachable_warnings(caplog)[1]
        clock.now += 30.0
        client.check_broker()
        assert len(unreachable_warnings(caplog)) == 3
        assert client.counters()["broker_unreachable_warnings"] == 3
        assert not client.connected
    finally:
        client.stop(timeout=0.5)
    clock.now += 300.0
    assert not client.check_broker(), "a stopped client warned"


def test_without_a_failed_attempt_the_first_warning_comes_after_the_grace(caplog, closed_url):
    """A broker host that drops packets: no attempt fails for a while, the WARN still comes."""
    caplog.set_level(logging.INFO, logger="coaty_bridge")
    clock = FakeClock()
    client = CoatyBridgeClient(BridgeConfig("robot_5", broker_url=closed_url), lambda u, t: None, clock=clock)
    client._down_since = clock.now          # as start() sets it, without connecting
    assert not client.check_broker()
    clock.now += FIRST_UNREACHABLE_WARN_AFTER
    assert client.check_broker()
    assert "robot_5" in unreachable_warnings(caplog)[0] and closed_url in unreachable_warnings(caplog)[0]


@pytest.mark.broker
def test_a_reachable_broker_gets_no_unreachable_warning(caplog, broker, wait_for):
    caplog.set_level(logging.INFO, logger="coaty_bridge")
    clock = FakeClock()
    client = CoatyBridgeClient(BridgeConfig("robot_6", broker_url=broker.url), lambda u, t: None, clock=clock)
    client.start()
    try:
        wait_for(lambda: client.subscribed, timeout=10, what="subscribed")
        clock.now += 120.0
        assert not client.check_broker()
        assert unreachable_warnings(caplog) == []
    finally:
        client.stop(timeout=0.5)


@pytest.mark.parametrize("value", [0, -1, True, "30"])
def test_bad_warn_interval_is_refused_naming_it(value):
    with pytest.raises(ValueError, match="broker_warn_interval"):
        BridgeConfig("robot_0", broker_warn_interval=value)


class FakeParams:
    """The parameter server of node robot_0/coaty_bridge, as a dict of full names."""

    def __init__(self, values):
        self.values = dict(values)

    def resolve(self, name):
        if name.startswith("~"):
            return "/robot_0/coaty_bridge/" + name[1:]
        return name if name.startswith("/") else "/robot_0/" + name

    def has(self, name):
        return self.resolve(name) in self.values

    def get(self, name, default=None):
        return self.values.get(self.resolve(name), default)


def never_wait(name):
    raise AssertionError("waited for %s" % name)


def test_url_from_the_default_says_so():
    choice = choose_broker_url(FakeParams({}), never_wait)
    assert choice.url == "mqtt://127.0.0.1:1883" and "default" in choice.source and choice.warning is None


def test_url_from_the_private_parameter_names_it():
    choice = choose_broker_url(FakeParams({"/robot_0/coaty_bridge/broker_url": "mqtt://10.0.0.1:1883"}), never_wait)
    assert choice.url == "mqtt://10.0.0.1:1883"
    assert choice.source == "private parameter /robot_0/coaty_bridge/broker_url" and choice.warning is None


def test_url_from_the_parameter_named_by_broker_url_param():
    params = FakeParams({"/robot_0/coaty_bridge/broker_url_param": "/fleet/broker_url"})
    choice = choose_broker_url(params, lambda name: "mqtt://127.0.0.1:4242" if name == "/fleet/broker_url" else None)
    assert choice.url == "mqtt://127.0.0.1:4242" and "/fleet/broker_url" in choice.source and choice.warning is None
    # a relative name is the robot's namespace parameter
    params = FakeParams({"/robot_0/coaty_bridge/broker_url_param": "fleet_broker"})
    choice = choose_broker_url(params, lambda name: "mqtt://127.0.0.1:4343")
    assert "/robot_0/fleet_broker" in choice.source


def test_leftover_private_url_overriding_the_launchs_broker_is_warned():
    params = FakeParams({"/robot_0/coaty_bridge/broker_url": "mqtt://127.0.0.1:1999",      # from an old run
                         "/robot_0/coaty_bridge/broker_url_param": "/fleet/broker_url",    # the launch's
                         "/fleet/broker_url": "mqtt://127.0.0.1:4242"})
    choice = choose_broker_url(params, never_wait)
    assert choice.url == "mqtt://127.0.0.1:1999"          # the documented precedence holds ...
    assert "private parameter /robot_0/coaty_bridge/broker_url" in choice.source
    for shown in ("/robot_0/coaty_bridge/broker_url", "mqtt://127.0.0.1:1999", "/fleet/broker_url",
                  "mqtt://127.0.0.1:4242", "rosparam delete"):
        assert shown in choice.warning                     # ... and is said, with both names and values
    # the broker's parameter not set yet: still said
    del params.values["/fleet/broker_url"]
    assert "not set yet" in choose_broker_url(params, never_wait).warning
    # the same URL in both: nothing to warn about
    params.values["/fleet/broker_url"] = "mqtt://127.0.0.1:1999"
    assert choose_broker_url(params, never_wait).warning is None


def test_bad_broker_url_param_is_refused_naming_it():
    with pytest.raises(ValueError, match="broker_url_param"):
        choose_broker_url(FakeParams({"/robot_0/coaty_bridge/broker_url_param": 5}), never_wait)
