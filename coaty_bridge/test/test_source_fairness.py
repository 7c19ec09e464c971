"""Fair delivery and the per-sender rate limit (issue 27, item 3), through the client's MQTT callback
with a fake clock and the inbox served step by step: no broker, no wall clock, no timing. The whole
path over a real mosquitto is measured by scripts/bench_flood (`make bench NAME=flood`)."""
import uuid as uuidlib
from types import SimpleNamespace

import pytest

from coaty_bridge import codec
from coaty_bridge.client import BridgeConfig, CoatyBridgeClient
from sharing_msgs.authority import FairQueue
from coaty_bridge.topics import Topic

OT = codec.DEFAULT_OBJECT_TYPE
FLOODER = "7c9e6679-7425-40de-944b-e07fc1f90ae7"
GOOD = "16fd2706-8baf-433b-82eb-8c7fada847da"


class Clock:
    def __init__(self):
        self.now = 1000.0

    def __call__(self):
        return self.now


def robot(clock, **config):
    delivered = []
    client = CoatyBridgeClient(BridgeConfig("robot_1", heartbeat_interval=1.0, **config),
                               lambda update, topic: delivered.append((topic.source_id, update.uuid)),
                               clock=clock, heartbeats=False)
    return client, delivered


def advertise(client, sender, make_update, source):
    update = make_update(uuid=str(uuidlib.uuid4()), source=source)
    topic = str(Topic("fleet", "ADV", sender, object_type=OT))
    client._on_mqtt_message(None, None, SimpleNamespace(
        topic=topic, payload=codec.advertise_payload(codec.obstacle_to_object(update, OT))))
    return update.uuid


def serve_all(client):
    while len(client._inbox):
        client.serve_one(timeout=0)


def test_fair_queue_serves_senders_in_turn():
    queue = FairQueue(max_per_key=10000)
    for i in range(1000):
        queue.put("flood", i)
    queue.put("good", "g")
    order = [queue.pop() for _ in range(4)]
    assert order[:2] == [("flood", 0), ("good", "g")]   # behind one flood message, not 1000
    assert order[2:] == [("flood", 1), ("flood", 2)]
    assert len(queue) == 997 and queue.pop() == ("flood", 3)   # the flood itself stays in order


def test_a_queued_flood_does_not_hold_back_another_senders_obstacle(make_update):
    clock = Clock()
    client, delivered = robot(clock, source_message_rate=1000.0, source_message_burst=5000)
    flood = [advertise(client, FLOODER, make_update, "robot_9") for _ in range(500)]
    good = advertise(client, GOOD, make_update, "robot_2")
    client.serve_one(timeout=0)
    client.serve_one(timeout=0)
    assert (GOOD, good) in delivered[:2], delivered[:2]
    serve_all(client)
    # nothing lost: every flood message within the limits is delivered, in its sender's order
    assert [u for s, u in delivered if s == FLOODER] == flood
    assert client.counters()["received"] == 501


def test_a_senders_obstacles_beyond_its_rate_are_dropped_before_parsing(make_update):
    clock = Clock()
    client, delivered = robot(clock, source_message_rate=2.0, source_message_burst=5)
    for _ in range(20):
        advertise(client, FLOODER, make_update, "robot_9")
    good = advertise(client, GOOD, make_update, "robot_2")
    counters = client.counters()
    assert counters["dropped.source_rate_limited"] == 15
    assert counters["dropped_source_rate_limited.%s" % FLOODER] == 15
    assert counters["inbox_length"] == 6
    serve_all(client)
    assert (GOOD, good) in delivered and len(delivered) == 6
    clock.now += 1.0      # two more tokens
    for _ in range(3):
        advertise(client, FLOODER, make_update, "robot_9")
    assert client.counters()["dropped.source_rate_limited"] == 16
    serve_all(client)
    assert len(delivered) == 8


def test_a_full_sender_queue_drops_only_that_senders_messages(make_update):
    clock = Clock()
    client, delivered = robot(clock, source_queue_size=3)
    for _ in range(10):
        advertise(client, FLOODER, make_update, "robot_9")
    good = advertise(client, GOOD, make_update, "robot_2")
    counters = client.counters()
    assert counters["dropped.source_queue_full"] == 7
    assert counters["dropped_source_queue_full.%s" % FLOODER] == 7
    serve_all(client)
    assert (GOOD, good) in delivered and len(delivered) == 4


def test_bad_source_limits_are_refused():
    for name, value in (("source_message_rate", 0), ("source_message_burst", 0), ("source_queue_size", -1),
                        ("source_message_burst", 1.5)):
        with pytest.raises(ValueError, match=name):
            BridgeConfig("robot_1", **{name: value})
