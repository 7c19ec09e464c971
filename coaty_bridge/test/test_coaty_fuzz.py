"""Fuzz: generated bad payloads through the codec and through the MQTT callback.
Every one must be dropped with one log line and one counter; nothing raises; the
good messages mixed in between all arrive."""
import json
import logging
import random
import uuid as uuidlib
from types import SimpleNamespace

from hypothesis import given, settings, strategies as st

from coaty_bridge import codec
from coaty_bridge.client import BridgeConfig, CoatyBridgeClient
from coaty_bridge.errors import CoatyError
from coaty_bridge.topics import Topic

OT = codec.DEFAULT_OBJECT_TYPE
LIMITS = codec.CodecLimits(max_payload_bytes=4096, max_indexes=500)
PEER = "7c9e6679-7425-40de-944b-e07fc1f90ae7"
ADV_TOPIC = str(Topic("fleet", "ADV", PEER, object_type=OT))
DSC_TOPIC = str(Topic("fleet", "DSC", PEER, correlation_id=str(uuidlib.UUID(int=1, version=4))))

# For each field, values that are certainly invalid there.
BAD_VALUES = {
    "objectType": [None, 3, "", "org.other.Type", ["x"]],
    "coreType": [None, "Identity", 0, "coatyobject"],
    "objectId": [None, 12, "", "robot_0", "0f8fad5b-d9cb-469f-a165-70867728950"],
    "name": [None, 5, [], {}],
    "uuid": [None, 5, "xyz", "0f8fad5b-d9cb-469f-a165-70867728950e"],
    "source": [None, 0, "", "robot/1", "robot+1", "robot#", "a\u0000b", ["robot_1"]],
    "version": [None, 0, -3, 1.5, "2", True, 2 ** 60, [], {}],
    "stamp": [None, "t", -1, [], True],
    "frameId": [None, 1, ["map"], "x" * 300],
    "deadline": [None, -1, 2 ** 33, 0.5, "60", False],
    "rectangle": [None, [], [0, 0, 1], [0, 0, 1, 1, 1], [1, 0, 0, 1], [0, 1, 1, 0], "0,0,1,1", [0, None, 1, 1]],
    "resolution": [None, 0, -0.05, "0.05", [0.05]],
    "origin": [None, [0], [0, 0, 0], ["0", 0], 0],
    "size": [None, [10], [0, 10], [10, -1], [1.5, 10], "10x10", [2 ** 20, 2 ** 20]],
    "markedIndexes": [None, 5, [100], [-1], [1, "2"], [0.5], "!!", "gA==", {"a": 1}, list(range(101))],
    "clearedIndexes": [None, 5, [100], [-1], [True], "AAA=", list(range(200))],
}


def good_object(rng):
    marked = sorted(rng.sample(range(100), rng.randint(1, 20)))
    origin_x, origin_y = rng.uniform(-50, 50), rng.uniform(-50, 50)
    update = codec.ObstacleUpdate(
        uuid=str(uuidlib.UUID(int=rng.getrandbits(128), version=4)), source="robot_%d" % rng.randint(0, 9),
        version=rng.randint(1, 10 ** 6), stamp=rng.uniform(0, 2e9), frame_id="map",
        deadline=rng.randint(1, 3600), rectangle=(origin_x, origin_y, origin_x + 0.5, origin_y + 0.5),
        resolution=0.05, origin_x=origin_x, origin_y=origin_y, size_x=10, size_y=10,
        marked=tuple(marked), cleared=())
    return codec.obstacle_to_object(update, OT, compact_indexes=rng.random() < 0.5), update


def bad_payloads(rng, count):
    """Yields (kind, bytes) pairs, each certainly invalid for LIMITS."""
    kinds = ["field", "missing", "nan", "truncated", "garbage", "utf8", "toplevel", "oversize",
             "no_object", "private"]
    for i in range(count):
        kind = kinds[i % len(kinds)]
        obj, _ = good_object(rng)
        if kind == "field":
            key = rng.choice(sorted(BAD_VALUES))
            obj[key] = rng.choice(BAD_VALUES[key])
            if obj[key] is None:
                del obj[key]
            data = json.dumps({"object": obj}).encode()
        elif kind == "missing":
            del obj[rng.choice(sorted(BAD_VALUES))]
            data = json.dumps({"object": obj}).encode()
        elif kind == "nan":
            key = rng.choice(["stamp", "resolution", "version", "deadline"])
            obj[key] = rng.choice([float("nan"), float("inf"), float("-inf")])
            data = json.dumps({"object": obj}).encode()
        elif kind == "truncated":
            text = json.dumps({"object": obj}).encode()
            data = text[:rng.randrange(len(text) - 1)]
        elif kind == "garbage":
            data = bytes(rng.getrandbits(8) for _ in range(rng.randint(0, 200)))
            if data.strip().startswith((b"{", b"[", b'"')) or data.strip()[:1].isdigit():
                data = b"}" + data
        elif kind == "utf8":
            data = json.dumps({"object": obj}).encode().replace(b'"map"', b'"m\xffp"')
        elif kind == "toplevel":
            data = json.dumps(rng.choice([[obj], 5, "object", None, True, []])).encode()
        elif kind == "oversize":
            obj["padding"] = "x" * LIMITS.max_payload_bytes
            data = json.dumps({"object": obj}).encode()
        elif kind == "no_object":
            data = json.dumps({"objects": [obj]}).encode()
        else:
            data = json.dumps({"object": obj, "privateData": rng.choice([[], "x", 3])}).encode()
        yield kind, data


def test_codec_rejects_every_generated_bad_payload():
    rng = random.Random(1234)
    kinds = set()
    for kind, payload in bad_payloads(rng, 1500):
        try:
            codec.decode_advertise(codec.parse_payload(payload, LIMITS), OT, LIMITS)
        except CoatyError:
            kinds.add(kind)
            continue
        raise AssertionError("accepted bad %s payload %r" % (kind, payload[:200]))
    assert len(kinds) == 10


def make_client(received):
    config = BridgeConfig("robot_9", broker_url="mqtt://127.0.0.1:1", max_payload_bytes=LIMITS.max_payload_bytes,
                          max_indexes=LIMITS.max_indexes)
    return CoatyBridgeClient(config, lambda update, topic: received.append(update))


def test_client_callback_drops_bad_and_keeps_good_messages(caplog):
    rng = random.Random(99)
    received, expected = [], []
    client = make_client(received)
    bad = 0
    caplog.set_level(logging.WARNING, logger="coaty_bridge")
    for i, (kind, payload) in enumerate(bad_payloads(rng, 1200)):
        client.on_message(None, None, SimpleNamespace(topic=ADV_TOPIC, payload=payload))
        bad += 1
        if i % 7 == 0:  # bad topics: wrong version, source ids, names
            topic = rng.choice([ADV_TOPIC.replace("coaty/3/", "coaty/2/"),
                                ADV_TOPIC.replace(PEER, "robot_1"),
                                "coaty/3/fle+et/ADV::%s/%s" % (OT, PEER),
                                DSC_TOPIC.rsplit("/", 1)[0] + "/nope"])
            obj, _ = good_object(rng)
            client.on_message(None, None, SimpleNamespace(topic=topic, payload=codec.advertise_payload(obj)))
            bad += 1
        if i % 5 == 0:  # a malformed Discover
            client.on_message(None, None, SimpleNamespace(topic=DSC_TOPIC, payload=payload))
            bad += 1
        if i % 10 == 0:
            obj, update = good_object(rng)
            expected.append(update)
            client.on_message(None, None, SimpleNamespace(topic=ADV_TOPIC, payload=codec.advertise_payload(obj)))
    counters = client.counters()
    dropped = {k: v for k, v in counters.items() if k.startswith("dropped.")}
    assert sum(dropped.values()) == bad, dropped
    assert "dropped.internal_error" not in dropped
    for reason in ("invalid_json", "non_finite_number", "wrong_type", "missing_field", "oversized",
                   "wrong_protocol_version", "invalid_name", "invalid_source_id", "out_of_range"):
        assert dropped.get("dropped." + reason), reason
    assert received == expected
    assert counters["received"] == len(expected)
    drops_logged = [r for r in caplog.records if "dropped" in r.getMessage()]
    assert len(drops_logged) == bad
    assert all("robot_9" in r.getMessage() for r in drops_logged)


JSON = st.recursive(st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False, allow_infinity=False)
                    | st.text(max_size=10),
                    lambda children: st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=8), children, max_size=4),
                    max_leaves=20)


@settings(max_examples=400, derandomize=True, deadline=None)
@given(st.dictionaries(st.sampled_from(sorted(BAD_VALUES) + ["x"]), JSON, max_size=16))
def test_arbitrary_json_objects_decode_or_raise_coaty_errors(obj):
    try:
        codec.obstacle_from_object(dict(obj, objectType=OT), OT, LIMITS)
    except CoatyError:
        pass
