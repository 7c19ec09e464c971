"""Authenticated sources (issue 15, item 3) on a real mosquitto: per-robot credentials, the
shipped ACL (config/mosquitto_acl.conf: publish only under one's own sourceId), the bridge's
source check, and the same over mqtts:// with a CA and per-robot client certificates made by
openssl."""
import functools
import os
import shutil
import subprocess
import uuid as uuidlib

import pytest

from coaty_bridge import codec
from coaty_bridge.broker import Broker
from coaty_bridge.client import BridgeConfig, CoatyBridgeClient, _make_paho_client
from coaty_bridge.identity import identity_for
from coaty_bridge.pki import make_ca, make_cert
from polling import join_after, wait_until

pytestmark = pytest.mark.broker
OT = codec.DEFAULT_OBJECT_TYPE
NS = "fleet"
ROBOTS = ("robot_0", "robot_1", "robot_2", "robot_3")
ACL = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "config", "mosquitto_acl.conf")
WAIT = 15.0


wait_for = functools.partial(wait_until, timeout=WAIT)


def obstacle(source, **fields):
    values = dict(uuid=str(uuidlib.uuid4()), source=source, version=1, stamp=10.0, frame_id="map", deadline=60,
                  rectangle=(0.0, 0.0, 1.0, 1.0), resolution=0.05, origin_x=0.0, origin_y=0.0, size_x=100,
                  size_y=100, marked=(5, 6), cleared=())
    values.update(fields)
    return codec.ObstacleUpdate(**values)


def adv(source_id, update):
    return ("coaty/3/%s/ADV::%s/%s" % (NS, OT, source_id),
            codec.advertise_payload(codec.obstacle_to_object(update, OT)))


class RawClient:
    """A plain paho client logged in as someone (no bridge logic): publishes what it is told,
    records what it receives."""

    def __init__(self, port, username=None, password=None, tls=None):
        self.received, self.refused, self.connected = [], [], False
        self.client = _make_paho_client("raw-" + uuidlib.uuid4().hex[:10])
        if tls:
            self.client.tls_set(ca_certs=tls[0], certfile=tls[1], keyfile=tls[2])
        if username:
            self.client.username_pw_set(username, password)
        self.client.on_connect = self._on_connect
        # connected once the broker acknowledged the subscription: before it, what others publish may not arrive
        self.client.on_subscribe = lambda *args: setattr(self, "connected", True)
        self.client.on_message = lambda c, u, m: self.received.append((m.topic, bytes(m.payload)))
        self.client.connect_async("127.0.0.1", port)
        self.client.loop_start()

    def _on_connect(self, client, userdata, flags, rc, properties=None):
        if rc == 0:
            client.subscribe("coaty/#")
        else:
            self.refused.append(rc)

    def publish(self, topic, payload):
        self.client.publish(topic, payload).wait_for_publish(5)

    def topics(self):
        return [t for t, _ in self.received]

    def close(self):
        self.client.disconnect()
        self.client.loop_stop()


@pytest.fixture
def secured_broker(tmp_path):
    """mosquitto with per-robot passwords (login = identity id) and the shipped ACL."""
    if not shutil.which("mosquitto_passwd"):
        pytest.skip("mosquitto_passwd not installed")
    passwords = str(tmp_path / "passwords")
    for i, robot in enumerate(ROBOTS):
        subprocess.run(["mosquitto_passwd", "-b"] + (["-c"] if i == 0 else []) +
                       [passwords, identity_for(NS, robot), "pw-" + robot], check=True, timeout=30)
    with Broker(allow_anonymous=False, extra_config=["password_file " + passwords, "acl_file " + ACL]) as broker:
        yield broker


@pytest.fixture
def cleanup():
    items = []
    yield items
    for item in reversed(items):
        item.stop(timeout=0.5) if isinstance(item, CoatyBridgeClient) else item.close()


def bridge(robot, url, received, cleanup, **config):
    config.setdefault("password", "pw-" + robot)
    client = CoatyBridgeClient(BridgeConfig(robot, broker_url=url, namespace=NS, authenticate_sources=True,
                                            reconnect_min_delay=0.2, reconnect_max_delay=0.5, **config),
                               lambda u, t: received.append(u))
    cleanup.append(client)
    client.start()
    return client


def test_identity_is_derived_from_the_name_and_a_mismatching_one_is_refused():
    config = BridgeConfig("robot_0", namespace=NS, authenticate_sources=True)
    assert config.identity_id == identity_for(NS, "robot_0") != identity_for(NS, "robot_1")
    assert config.username == config.identity_id
    with pytest.raises(ValueError, match="identity_id"):
        BridgeConfig("robot_0", namespace=NS, authenticate_sources=True, identity_id=str(uuidlib.uuid4()))


def test_wrong_credentials_and_anonymous_logins_are_refused(secured_broker, cleanup):
    wrong = bridge("robot_0", secured_broker.url, [], cleanup, password="not-the-password")
    stranger = RawClient(secured_broker.port)
    cleanup.append(stranger)
    wait_for(lambda: wrong.counters().get("connect_failures", 0) >= 1, "robot_0's refused login")
    wait_for(lambda: stranger.refused, "the anonymous client's refused login")
    assert not wrong.connected and not stranger.connected
    right = bridge("robot_1", secured_broker.url, [], cleanup)
    wait_for(lambda: right.subscribed, "robot_1 with its own credentials")
    assert not wrong.connected


def test_broker_refuses_publishing_under_another_robots_source_id(secured_broker, cleanup):
    robot_1 = RawClient(secured_broker.port, identity_for(NS, "robot_1"), "pw-robot_1")
    watcher = RawClient(secured_broker.port, identity_for(NS, "robot_2"), "pw-robot_2")
    cleanup += [robot_1, watcher]
    wait_for(lambda: robot_1.connected and watcher.connected, "both logged in")
    forged_topic, payload = adv(identity_for(NS, "robot_0"), obstacle("robot_0"))
    own_topic, own_payload = adv(identity_for(NS, "robot_1"), obstacle("robot_1"))
    robot_1.publish(forged_topic, payload)
    robot_1.publish(own_topic, own_payload)   # same client, sent after: arrives after the forged one would
    wait_for(lambda: own_topic in watcher.topics(), "robot_1's own event")
    assert forged_topic not in watcher.topics()


def test_bridge_drops_a_forged_source_and_accepts_updates_under_the_senders_name(secured_broker, cleanup):
    received = []
    receiver = bridge("robot_2", secured_broker.url, received, cleanup)
    robot_1 = RawClient(secured_broker.port, identity_for(NS, "robot_1"), "pw-robot_1")
    cleanup.append(robot_1)
    wait_for(lambda: receiver.subscribed and robot_1.connected, "logged in")
    own_id = identity_for(NS, "robot_1")
    forged = obstacle("robot_0")                       # robot_1 speaking for robot_0
    clear_of_other = obstacle("robot_1", uuid=forged.uuid, version=2, marked=(), cleared=(5,))
    honest = obstacle("robot_1")
    for update in (forged, clear_of_other, honest):
        robot_1.publish(*adv(own_id, update))
    wait_for(lambda: len(received) == 2, "the two honest events")
    assert received == [clear_of_other, honest]
    assert receiver.counters()["dropped.forged_source"] == 1


def test_two_bridges_share_through_the_secured_broker(secured_broker, cleanup):
    got_1 = []
    robot_0 = bridge("robot_0", secured_broker.url, [], cleanup)
    join_after(robot_0, lambda: bridge("robot_1", secured_broker.url, got_1, cleanup), wait_for)
    update = obstacle("robot_0")
    robot_0.publish_obstacle(update)
    wait_for(lambda: got_1 == [update], "robot_0's obstacle at robot_1")


def test_a_late_joiner_gets_a_gone_creators_obstacle_from_its_holders_under_their_names(secured_broker, cleanup):
    """Receivers take an obstacle only from the robot its source names. While the creator is a live peer it answers
    for its obstacle alone; once it has left, a holder answers under its own name (as any update of another robot's
    obstacle is sent), so the joining robot learns the obstacle instead of nothing."""
    peers = dict(heartbeat_interval=0.2, peer_heartbeat_interval=0.2, liveness_timeout=30.0)
    creator = bridge("robot_0", secured_broker.url, [], cleanup, **peers)
    holder = bridge("robot_1", secured_broker.url, [], cleanup, **peers)
    wait_for(lambda: holder.liveness.alive("robot_0") and creator.liveness.alive("robot_1"), "robot_0 and robot_1 live")
    by_0 = obstacle("robot_0")
    creator.set_current_obstacles([by_0])
    holder.set_current_obstacles([by_0])

    while_alive = []
    bridge("robot_2", secured_broker.url, while_alive, cleanup, **peers)
    wait_for(lambda: holder.counters().get("resolves_left_to_creator", 0) == 1, "robot_1 leaving it to robot_0")
    wait_for(lambda: [(u.uuid, u.source) for u in while_alive] == [(by_0.uuid, "robot_0")], "robot_0's own answer")

    creator.stop(timeout=2.0)   # a clean stop: its identity withdrawn
    wait_for(lambda: not holder.liveness.alive("robot_0"), "robot_0 gone at robot_1")
    after_it_left = []
    joiner = bridge("robot_3", secured_broker.url, after_it_left, cleanup, **peers)
    wait_for(lambda: len(after_it_left) == 1, "robot_0's obstacle at robot_3, answered by robot_1")
    answer = after_it_left[0]
    assert (answer.uuid, answer.source, answer.version, answer.marked) == (by_0.uuid, "robot_1", by_0.version,
                                                                          by_0.marked)
    assert joiner.counters().get("dropped.forged_source", 0) == 0


def test_with_handlers_a_robot_joining_after_the_creator_left_holds_its_obstacle(secured_broker, cleanup):
    """The same through each robot's real SharingHandler behind its bridge (wired as the nodes wire them): robot_2
    holds robot_0's obstacle after robot_0 left, taking it as robot_1's word, with nothing dropped on the way."""
    from test_peer_authority import Clock, Robot   # (handler + bridge of one robot; puts the handler on the path)
    clock = Clock()

    def join(name):
        robot = Robot(name, secured_broker.url, clock, namespace=NS, authenticate_sources=True, password="pw-" + name,
                      heartbeat_interval=0.2, peer_heartbeat_interval=0.2, liveness_timeout=30.0)
        cleanup.append(robot.client)
        robot.client.start()
        return robot

    creator, holder = join("robot_0"), join("robot_1")
    # each heard the other's heartbeats: both are subscribed, so the obstacle advertised next reaches robot_1
    wait_for(lambda: holder.client.liveness.alive("robot_0") and creator.client.liveness.alive("robot_1"),
             "robot_0 and robot_1 live")
    uuid = creator.add([1.0, 1.0, 1.4, 1.4])
    wait_for(lambda: uuid in holder.held(), "robot_0's obstacle at robot_1")
    creator.client.stop(timeout=2.0)
    wait_for(lambda: not holder.client.liveness.alive("robot_0"), "robot_0 gone at robot_1")

    joiner = join("robot_2")
    wait_for(lambda: uuid in joiner.held(), "robot_0's obstacle at robot_2, which joined after robot_0 left")
    source, _rectangle, cells = joiner.held()[uuid]
    assert source == "robot_1" and cells == holder.held()[uuid][2]
    assert joiner.client.counters().get("dropped.forged_source", 0) == 0
    assert not [name for name, count in joiner.handler.counters.items() if name.startswith("dropped") and count]


@pytest.fixture
def tls_fleet(tmp_path):
    """A CA, a broker certificate for 127.0.0.1 and one client certificate per robot with
    CN = its identity id; mosquitto requires a certificate and uses its CN as the login."""
    if not shutil.which("openssl"):
        pytest.skip("openssl not installed")
    pki = str(tmp_path / "pki")
    ca = make_ca(pki)
    server = make_cert(ca, pki, "broker", ip="127.0.0.1")
    robots = {robot: make_cert(ca, pki, identity_for(NS, robot)) for robot in ROBOTS}
    config = ["cafile " + ca.cert, "certfile " + server.cert, "keyfile " + server.key,
              "require_certificate true", "use_identity_as_username true", "acl_file " + ACL]
    with Broker(allow_anonymous=False, extra_config=config) as broker:
        yield broker, ca, robots


def test_bridges_over_mqtts_with_client_certificates(tls_fleet, cleanup):
    broker, ca, certs = tls_fleet
    url = "mqtts://127.0.0.1:%d" % broker.port
    got_1 = []

    def tls_bridge(robot, sink):
        # no password: the broker takes the login from the certificate's CN
        return bridge(robot, url, sink, cleanup, password="",
                      tls_ca=ca.cert, tls_cert=certs[robot].cert, tls_key=certs[robot].key)
    robot_0 = tls_bridge("robot_0", [])
    join_after(robot_0, lambda: tls_bridge("robot_1", got_1), wait_for)
    update = obstacle("robot_0")
    robot_0.publish_obstacle(update)
    wait_for(lambda: got_1 == [update], "robot_0's obstacle at robot_1 over TLS")

    # robot_2's certificate does not let it publish under robot_0's sourceId
    robot_2 = RawClient(broker.port, tls=(ca.cert, certs["robot_2"].cert, certs["robot_2"].key))
    cleanup.append(robot_2)
    wait_for(lambda: robot_2.connected, "robot_2 over TLS")
    forged_topic, payload = adv(identity_for(NS, "robot_0"), obstacle("robot_0"))
    own_topic, own_payload = adv(identity_for(NS, "robot_2"), obstacle("robot_2"))
    robot_2.publish(forged_topic, payload)
    robot_2.publish(own_topic, own_payload)
    wait_for(lambda: len(got_1) == 2, "robot_2's own obstacle at robot_1")
    assert [u.source for u in got_1] == ["robot_0", "robot_2"]
    assert not connects_without_certificate(broker.port, ca.cert)


def connects_without_certificate(port, ca_cert):
    """True when an MQTT CONNECT over TLS without a client certificate is accepted."""
    client = _make_paho_client("no-cert-" + uuidlib.uuid4().hex[:8])
    client.tls_set(ca_certs=ca_cert)
    try:
        client.connect("127.0.0.1", port)
        for _ in range(50):  # read the CONNACK, if any comes
            if client.loop(0.1) != 0:
                return False
            if client.is_connected():
                return True
        return False
    except (OSError, ValueError):  # ssl.SSLError is an OSError: the handshake was refused
        return False
    finally:
        try:
            client.disconnect()
        except OSError:
            pass
