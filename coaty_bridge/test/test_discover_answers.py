"""Who answers a joining robot's Discover with another robot's obstacle (``discover_answers``).

Before, every robot answered with every obstacle it held: a robot joining a fleet of N robots that
hold M obstacles got N x M Resolves (100 robots, 1,000 obstacles: ~100,000, ~48 MB). Now the
creator of an obstacle answers for it while it is a live peer; once its identity is withdrawn (a
clean stop, or the last will the broker sends for a robot it lost) or it is not heard, every robot
holding the obstacle answers, as before. Bridges against a real mosquitto started by each test.
"""
import pytest

import uuid as uuidlib

from coaty_bridge import codec
from coaty_bridge.client import BridgeConfig, CoatyBridgeClient
from coaty_bridge.identity import identity_for
from coaty_bridge.topics import Topic

pytestmark = pytest.mark.broker

# Peers learn each other within a fraction of a second; a peer counts as alive for 30 s after it was
# last heard, so a loaded machine cannot make a live creator look gone mid-test.
FAST_PEERS = dict(heartbeat_interval=0.2, peer_heartbeat_interval=0.2, liveness_timeout=30.0)


def start_fleet(make_client, wait_for, names, **config):
    clients = [make_client(name, **FAST_PEERS, **config) for name in names]
    wait_for(lambda: all(c.liveness.alive(other) for c in clients for other in names if other != c.config.robot_name),
             timeout=10.0, what="every robot hears every other as a live peer")
    return clients


def start_listening(make_client, wait_for, name, **config):
    """A robot whose subscriptions are live (its own echo came back), so that a Discover sent next reaches it."""
    client = make_client(name, **config)
    wait_for(lambda: "own_echo_age" in client.liveness.values(), what=name + "'s own echo (its subscriptions live)")
    return client


def counter(client, name):
    return client.counters().get(name, 0)


def test_another_robots_obstacle_is_answered_by_its_creator_alone(make_client, make_update, wait_for):
    creator, holder_1, holder_2 = start_fleet(make_client, wait_for, ["robot_0", "robot_1", "robot_2"])
    by_0 = make_update(source="robot_0")
    by_1 = make_update(source="robot_1")
    for client in (creator, holder_1, holder_2):
        client.set_current_obstacles([by_0, by_1])
    sent_before = counter(holder_2, "resolves_sent")

    joiner = make_client("robot_3", **FAST_PEERS)
    wait_for(lambda: {u.uuid for u in joiner.received_updates} == {by_0.uuid, by_1.uuid},
             what="both obstacles at the joining robot")
    # robot_2 created neither: both are left to their live creators, and it sends nothing
    wait_for(lambda: counter(holder_2, "resolves_left_to_creator") == 2, what="robot_2 leaving both to their creators")
    assert counter(holder_2, "resolves_sent") == sent_before
    wait_for(lambda: counter(creator, "resolves_left_to_creator") == 1 and
             counter(holder_1, "resolves_left_to_creator") == 1, what="each creator answering only its own")


def test_with_discover_answers_everyone_every_holder_answers(make_client, make_update, wait_for):
    _creator, _holder_1, holder_2 = start_fleet(make_client, wait_for, ["robot_0", "robot_1", "robot_2"],
                                                discover_answers="everyone")
    by_0, by_1 = make_update(source="robot_0"), make_update(source="robot_1")
    holder_2.set_current_obstacles([by_0, by_1])
    sent_before = counter(holder_2, "obstacles_resolved")
    make_client("robot_3", **FAST_PEERS)
    wait_for(lambda: counter(holder_2, "obstacles_resolved") == sent_before + 2, what="robot_2 answering both")
    assert counter(holder_2, "resolves_left_to_creator") == 0


def test_a_creator_that_stopped_is_answered_for_by_everyone_holding_its_obstacle(make_client, make_update,
                                                                                 wait_for):
    creator, holder_1, holder_2 = start_fleet(make_client, wait_for, ["robot_0", "robot_1", "robot_2"])
    by_0 = make_update(source="robot_0")
    creator.stop(timeout=2.0)   # a clean stop: a leaving heartbeat and its identity withdrawn
    wait_for(lambda: not holder_1.liveness.alive("robot_0") and not holder_2.liveness.alive("robot_0"),
             what="robot_0 gone at both holders")
    for holder in (holder_1, holder_2):
        holder.set_current_obstacles([by_0])
    sent_before = [counter(h, "obstacles_resolved") for h in (holder_1, holder_2)]

    joiner = make_client("robot_3", **FAST_PEERS)
    wait_for(lambda: all(counter(h, "obstacles_resolved") == before + 1
                         for h, before in zip((holder_1, holder_2), sent_before)), what="both holders answering")
    wait_for(lambda: [u.uuid for u in joiner.received_updates] == [by_0.uuid] * 2, what="both answers at robot_3")


def test_the_last_will_of_a_lost_creator_hands_its_obstacles_to_the_fleet(make_client, make_update, observer,
                                                                          wait_for):
    creator, holder = start_fleet(make_client, wait_for, ["robot_0", "robot_1"])
    by_0 = make_update(source="robot_0")
    holder.set_current_obstacles([by_0])
    # exactly what the broker sends for robot_0 when it loses it (will_set in client.py); robot_0 itself
    # keeps running, so only the Deadvertise can make robot_1 answer
    observer.publish(str(Topic("fleet", "DAD", creator.identity_id)), codec.deadvertise_payload([creator.identity_id]))
    wait_for(lambda: counter(holder, "peers_departed") == 1, what="robot_1 taking the last will")
    assert not holder.liveness.alive("robot_0")
    sent_before = counter(holder, "obstacles_resolved")
    make_client("robot_3", **FAST_PEERS)
    wait_for(lambda: counter(holder, "obstacles_resolved") == sent_before + 1, what="robot_1 answering for robot_0")


def test_a_restarted_creator_asking_gets_its_obstacles_from_the_fleet(make_client, make_update, wait_for):
    """robot_0 restarts while the broker still holds its old session (a crash: the last will comes only
    after the keepalive), so the fleet still hears it. Its new instance names itself in its Identity advert
    before it asks: the fleet's copies are all that is left of its obstacles, so every holder answers."""
    _old_instance, holder = start_fleet(make_client, wait_for, ["robot_0", "robot_1"])
    by_0 = make_update(source="robot_0")
    holder.set_current_obstacles([by_0])
    sent_before = counter(holder, "obstacles_resolved")
    restarted = make_client("robot_0", **FAST_PEERS)
    wait_for(lambda: [u.uuid for u in restarted.received_updates] == [by_0.uuid], what="robot_0's obstacle back")
    assert holder.liveness.alive("robot_0")
    assert counter(holder, "obstacles_resolved") == sent_before + 1
    assert counter(holder, "resolves_left_to_creator") == 0


def test_discover_answers_is_checked():
    with pytest.raises(ValueError, match="discover_answers"):
        BridgeConfig("robot_0", discover_answers="nobody")
    with pytest.raises(ValueError, match="discover_answers"):
        BridgeConfig("robot_0", discover_answers=None)


def identity_advert(name, source_id):
    return (str(Topic("fleet", "ADV", source_id, core_type=codec.IDENTITY_CORE_TYPE)),
            codec.advertise_payload(codec.identity_object(source_id, name)))


def test_bad_identity_adverts_are_dropped_and_name_nobody():
    client = CoatyBridgeClient(BridgeConfig("robot_1", **FAST_PEERS), lambda update, topic: None)  # not started
    source_id = identity_for("fleet", "robot_0")
    topic, _good = identity_advert("robot_0", source_id)
    bad = [b"{not json", b'{"object": "robot_0"}', b'{"object": {"name": 7}}', b'{"object": {"name": "a/b"}}',
           b'{"object": {"objectType": "coaty.Identity"}}']
    for payload in bad:
        client.handle(topic, payload)
    dropped = sum(n for name, n in client.counters().items() if name.startswith("dropped."))
    assert dropped == len(bad)
    assert client._robot_of.get(source_id) is None
    client.handle(*identity_advert("robot_0", source_id))
    assert client._robot_of.get(source_id) == "robot_0"


def test_an_identity_advert_under_a_sourceid_not_derived_from_its_name_is_ignored_when_authenticating():
    client = CoatyBridgeClient(BridgeConfig("robot_1", authenticate_sources=True, **FAST_PEERS),
                               lambda update, topic: None)
    impostor = identity_for("fleet", "robot_9")
    client.handle(*identity_advert("robot_0", impostor))    # robot_9 claiming to be robot_0
    assert client._robot_of.get(impostor) is None
    assert client.counters().get("ignored") == 1
    client.handle(*identity_advert("robot_9", impostor))
    assert client._robot_of.get(impostor) == "robot_9"


def test_under_authenticated_sources_a_holder_answers_for_a_gone_creator_under_its_own_name(make_update):
    """Every authenticating receiver drops an obstacle whose source is not its sender (forged_source): a copy
    relayed under the creator's name would only cost the wire, and a robot joining after the creator left learnt
    nothing. The holder sends it under its own name instead, as any update of another robot's obstacle.
    (Through a secured broker: test_bridge_auth.py.)"""
    holder = CoatyBridgeClient(BridgeConfig("robot_1", authenticate_sources=True, **FAST_PEERS),
                               lambda update, topic: None)   # not started: what it sends is captured
    sent = []
    holder._send = lambda topic, payload, queue=True, **_: sent.append(payload)
    by_0, by_1 = make_update(source="robot_0"), make_update(source="robot_1")
    holder.set_current_obstacles([by_0, by_1])
    asker = identity_for("fleet", "robot_3")
    holder.handle(str(Topic("fleet", "DSC", asker, correlation_id=str(uuidlib.uuid4()))),
                  codec.discover_object_types_payload([codec.DEFAULT_OBJECT_TYPE]))
    answered = [u for payload in sent
                for u in codec.decode_resolve(codec.parse_payload(payload, codec.CodecLimits()),
                                              codec.DEFAULT_OBJECT_TYPE).obstacles]
    # robot_0 was never heard: it is gone, and its obstacle goes under robot_1's name, its uuid, version and cells kept
    assert sorted((u.uuid, u.source, u.version, u.marked) for u in answered) == sorted(
        [(by_0.uuid, "robot_1", by_0.version, by_0.marked), (by_1.uuid, "robot_1", by_1.version, by_1.marked)])
    assert holder.counters().get("resolved_under_own_name") == 1
    assert holder.counters().get("resolves_left_to_creator", 0) == 0


def test_a_discover_is_answered_in_batches_of_obstacles_each_within_the_payload_limit(make_client, make_update,
                                                                                        observer, wait_for):
    """One Resolve per obstacle cost a joining robot a message per obstacle per robot answering; the answers now
    go as RESOLVE_BATCH obstacles per Resolve (``relatedObjects``), fewer when max_payload_bytes is reached."""
    from coaty_bridge.client import RESOLVE_BATCH, RESOLVE_BATCH_BYTES
    many = [make_update(source="robot_0", marked=(880220 + i % 50 + 2000 * (i // 50),)) for i in range(150)]
    holder = start_listening(make_client, wait_for, "robot_0", **FAST_PEERS)
    holder.set_current_obstacles(many)
    joiner = make_client("robot_1", **FAST_PEERS)
    wait_for(lambda: len(joiner.received_updates) == len(many), what="150 obstacles at the joining robot")
    assert sorted(u.uuid for u in joiner.received_updates) == sorted(u.uuid for u in many)
    assert counter(holder, "obstacles_resolved") == len(many)
    # ~450 bytes each: 32 per Resolve within RESOLVE_BATCH_BYTES (at most RESOLVE_BATCH), so 5 Resolves, not 150
    sent = counter(holder, "resolves_sent")
    assert -(-len(many) // RESOLVE_BATCH) <= sent <= len(many) // 20, sent
    wait_for(lambda: len([t for t, _ in list(observer.messages) if "/RSV/%s/" % holder.identity_id in t]) == sent,
             what="the Resolves at the observer")
    resolves = [payload for topic, payload in list(observer.messages) if "/RSV/%s/" % holder.identity_id in topic]
    assert all(len(payload) <= RESOLVE_BATCH_BYTES for payload in resolves)
    holder.stop(timeout=2.0)
    joiner.stop(timeout=2.0)

    small = dict(FAST_PEERS, max_payload_bytes=2000)   # a few obstacles per Resolve
    holder_small = start_listening(make_client, wait_for, "robot_2", **small)
    holder_small.set_current_obstacles([make_update(source="robot_2", marked=(880220 + i % 50 + 2000 * (i // 50),)) for i in range(20)])
    joiner_small = make_client("robot_3", **small)
    wait_for(lambda: len(joiner_small.received_updates) == 20, what="all 20 at the second joiner")
    sent = counter(holder_small, "resolves_sent")
    assert 20 // 4 <= sent < 20, sent
    assert counter(joiner_small, "dropped.payload_too_large") == 0


def test_a_resolve_is_taken_just_inside_discover_window_and_ignored_just_outside(make_update):
    """A Resolve answers this robot's Discover only within discover_window (30 s) of it: at 29.9 s it is taken, at
    30.1 s it is ignored (counted), whatever it carries."""
    now = [1000.0]
    received = []
    client = CoatyBridgeClient(BridgeConfig("robot_1", discover_window=30.0, **FAST_PEERS),
                               lambda update, topic: received.append(update.uuid), clock=lambda: now[0])  # not started
    client._send = lambda topic, payload, queue=True, **_: None
    client._discover_obstacles()
    (correlation_id,) = client._pending_discovers
    topic = str(Topic("fleet", "RSV", identity_for("fleet", "robot_0"), correlation_id=correlation_id))

    def resolve(update):
        return codec.resolve_payload(codec.obstacle_to_object(update, codec.DEFAULT_OBJECT_TYPE))
    inside, outside = make_update(), make_update()
    now[0] = 1000.0 + 29.9
    client.handle(topic, resolve(inside))
    assert received == [inside.uuid]
    ignored = counter(client, "ignored")
    now[0] = 1000.0 + 30.1
    client.handle(topic, resolve(outside))
    assert received == [inside.uuid], "a Resolve 30.1 s after the Discover was taken"
    assert counter(client, "ignored") == ignored + 1


def test_a_robot_receives_the_resolves_to_its_own_discovers_only(make_client, make_update, wait_for):
    """Each robot subscribes to the Resolves of its pending Discovers, not to every Resolve of the namespace: with
    the wildcard, every robot received every catch-up of every driving robot entering new obstacle areas. Checked
    after an ordered event: robot_0's Advertise sent after its Resolves reaches the bystander after them."""
    holder, bystander = start_fleet(make_client, wait_for, ["robot_0", "robot_2"])
    by_0 = make_update(source="robot_0")
    holder.set_current_obstacles([by_0])
    seen = []
    handle = bystander.handle

    def recording(topic_text, payload):
        seen.append(topic_text)
        handle(topic_text, payload)
    bystander.handle = recording
    joiner = make_client("robot_3", **FAST_PEERS)
    wait_for(lambda: by_0.uuid in {u.uuid for u in joiner.received_updates}, what="the obstacle at the joining robot")
    assert counter(holder, "resolves_sent") >= 1
    after = make_update(source="robot_0")
    holder.publish_obstacle(after)
    wait_for(lambda: after.uuid in {u.uuid for u in bystander.received_updates}, what="robot_0's later Advertise")
    assert not [t for t in seen if "/RSV/" in t], "a Resolve to robot_3's Discover reached robot_2"
    assert by_0.uuid in {u.uuid for u in joiner.received_updates}


def test_the_resolve_subscription_of_a_discover_ends_with_its_window():
    """Subscribed before the Discover goes out; unsubscribed at the first Discover after discover_window (30 s), not at
    one just inside it."""
    now = [1000.0]
    calls = []

    class Paho:
        def subscribe(self, topic, qos=0):
            calls.append(("sub", topic))

        def unsubscribe(self, topics):
            calls.append(("unsub", tuple(topics)))
    client = CoatyBridgeClient(BridgeConfig("robot_1", discover_window=30.0), lambda u, t: None, clock=lambda: now[0])
    client._mqtt = Paho()
    client._send = lambda topic, payload, queue=True, **_: calls.append(("send", topic))
    client._discover_obstacles()
    (first,) = client._pending_discovers
    assert calls[0] == ("sub", "coaty/+/fleet/RSV/+/" + first) and calls[1][0] == "send" and first in calls[1][1]
    now[0] += 29.9
    client._discover_obstacles()
    assert not [c for c in calls if c[0] == "unsub"]
    now[0] += 0.2   # the first is 30.1 s old
    client._discover_obstacles()
    assert [c for c in calls if c[0] == "unsub"] == [("unsub", ("coaty/+/fleet/RSV/+/" + first,))]
