import json
import math

import pytest

from coaty_bridge import codec
from coaty_bridge.codec import CodecLimits, obstacle_from_object, obstacle_to_object, parse_payload
from coaty_bridge.errors import (CoatyError, InvalidJsonError, InvalidNameError, InvalidPayloadError,
                                 MissingFieldError, NonFiniteNumberError, OutOfRangeError,
                                 PayloadTooLargeError, TooManyIndexesError, WrongTypeError)

OT = codec.DEFAULT_OBJECT_TYPE
REQUIRED = ["objectType", "coreType", "objectId", "name", "uuid", "source", "version", "stamp",
            "frameId", "deadline", "rectangle", "resolution", "origin", "size", "markedIndexes",
            "clearedIndexes"]


def wire(update, compact=True):
    """What a receiver parses: the object after a JSON round trip."""
    return json.loads(codec.advertise_payload(obstacle_to_object(update, OT, compact)))["object"]


@pytest.mark.parametrize("compact", [True, False])
def test_obstacle_survives_the_wire_with_every_field(make_update, compact):
    update = make_update(version=7, deadline=1, marked=(880220, 880269, 958269), cleared=())   # the rectangle's corners
    obj = wire(update, compact)
    assert obj["objectId"] == update.uuid and obj["coreType"] == "CoatyObject"
    assert obj["objectType"] == OT and "parentObjectId" not in obj
    assert obstacle_from_object(obj, OT) == update


def test_plain_and_compact_index_forms_mean_the_same_set(make_update):
    update = make_update()
    assert isinstance(wire(update, True)["markedIndexes"], str)
    assert wire(update, False)["markedIndexes"] == [880221, 880222, 882223]
    assert obstacle_from_object(wire(update, True), OT) == obstacle_from_object(wire(update, False), OT)


def test_javascript_integers_are_accepted_for_float_fields(make_update):
    obj = wire(make_update(), False)
    obj.update(resolution=1, origin=[0, -3], rectangle=[0, 0, 2, 2], stamp=12, version=2.0, markedIndexes=[6000],
               clearedIndexes=[6001])
    update = obstacle_from_object(obj, OT)
    assert update.resolution == 1.0 and isinstance(update.resolution, float)
    assert update.origin_y == -3.0 and update.rectangle == (0.0, 0.0, 2.0, 2.0)
    assert update.version == 2 and isinstance(update.version, int)


def test_duplicate_indexes_collapse_to_a_set(make_update):
    obj = wire(make_update(), False)
    obj["markedIndexes"] = [880223, 880221, 880223]
    assert obstacle_from_object(obj, OT).marked == (880221, 880223)


@pytest.mark.parametrize("key", REQUIRED)
def test_every_missing_field_is_named(make_update, key):
    obj = wire(make_update())
    del obj[key]
    with pytest.raises(MissingFieldError, match=key):
        obstacle_from_object(obj, OT)


@pytest.mark.parametrize("key, value, error", [
    ("version", "3", WrongTypeError),
    ("version", 1.5, WrongTypeError),
    ("version", 0, OutOfRangeError),
    ("version", 2 ** 53, OutOfRangeError),
    ("deadline", -1, OutOfRangeError),
    ("deadline", True, WrongTypeError),
    ("stamp", "now", WrongTypeError),
    ("stamp", -1.0, OutOfRangeError),
    ("resolution", 0, OutOfRangeError),
    ("resolution", None, WrongTypeError),
    ("rectangle", [0, 0, 1], WrongTypeError),
    ("rectangle", [2, 0, 1, 1], OutOfRangeError),
    ("rectangle", [0, "0", 1, 1], WrongTypeError),
    ("origin", {"x": 0}, WrongTypeError),
    ("size", [0, 10], OutOfRangeError),
    ("size", [2 ** 17, 2 ** 17], OutOfRangeError),
    ("size", 100, WrongTypeError),
    ("markedIndexes", [1, "2"], WrongTypeError),
    ("markedIndexes", [2000 * 2000], OutOfRangeError),
    ("markedIndexes", [-1], OutOfRangeError),
    ("markedIndexes", {"0": 1}, WrongTypeError),
    ("clearedIndexes", "!!notbase64", WrongTypeError),
    ("uuid", "7c9e6679-7425-40de-944b-e07fc1f90ae7", OutOfRangeError),
    ("objectId", "obstacle-1", OutOfRangeError),
    ("source", "robot/0", InvalidNameError),
    ("source", "robot+", InvalidNameError),
    ("source", "#", InvalidNameError),
    ("source", 17, WrongTypeError),
    ("objectType", "org.other.Thing", WrongTypeError),
    ("coreType", "Identity", WrongTypeError),
    ("frameId", ["map"], WrongTypeError),
    ("stamp", 1e400, NonFiniteNumberError),
])
def test_bad_field_values_raise_errors_naming_them(make_update, key, value, error):
    obj = wire(make_update())
    obj[key] = value
    with pytest.raises(error) as info:
        obstacle_from_object(obj, OT)
    assert isinstance(info.value, CoatyError) and isinstance(info.value, ValueError)


def test_index_count_is_bounded_by_the_grid_and_the_limit(make_update):
    obj = wire(make_update(size_x=4, size_y=2, marked=(0,), cleared=(), rectangle=(-10, -20, -9.8, -19.9)), False)
    obj["markedIndexes"] = list(range(8))
    assert len(obstacle_from_object(obj, OT).marked) == 8
    obj["markedIndexes"] = list(range(8)) + [1]
    with pytest.raises(TooManyIndexesError):
        obstacle_from_object(obj, OT)
    obj["markedIndexes"] = list(range(5))
    with pytest.raises(TooManyIndexesError):
        obstacle_from_object(obj, OT, CodecLimits(max_indexes=4))


def test_parse_payload_rejects_bad_json_nan_and_oversize():
    limits = CodecLimits(max_payload_bytes=100)
    assert parse_payload(b'{"a": 1}', limits) == {"a": 1}
    with pytest.raises(InvalidJsonError):
        parse_payload(b'{"a": ', limits)
    with pytest.raises(InvalidJsonError):
        parse_payload(b'\xff\xfe{}', limits)
    for constant in (b"NaN", b"Infinity", b"-Infinity"):
        with pytest.raises(NonFiniteNumberError):
            parse_payload(b'{"a": %s}' % constant, limits)
    with pytest.raises(WrongTypeError):
        parse_payload(b'[1, 2]', limits)
    with pytest.raises(PayloadTooLargeError, match="101 bytes"):
        parse_payload(b'{"a": "' + b"x" * 92 + b'"}', limits)


def test_outgoing_json_never_contains_nan():
    with pytest.raises(ValueError):
        codec.dump({"x": math.nan})


def test_update_value_validates_itself(make_update):
    with pytest.raises(OutOfRangeError, match="not-a-uuid"):
        make_update(uuid="not-a-uuid")
    with pytest.raises(NonFiniteNumberError, match="origin_x"):
        make_update(origin_x=math.inf)
    with pytest.raises(OutOfRangeError, match="marked_indexes 4000000"):
        make_update(marked=(4000000,))


IDENT = "0f8fad5b-d9cb-469f-a165-70867728950e"


@pytest.mark.parametrize("data, identity, obstacles", [
    ({"coreTypes": ["Identity"]}, True, False),
    ({"objectTypes": ["coaty.Identity"]}, True, False),
    ({"objectId": IDENT}, True, False),
    ({"objectId": "7c9e6679-7425-40de-944b-e07fc1f90ae7"}, False, False),
    ({"objectTypes": [OT]}, False, True),
    ({"objectTypes": [OT, "coaty.Identity"]}, True, True),
    ({"coreTypes": ["Task"]}, False, False),
    ({"externalId": "x", "objectTypes": [OT]}, False, False),
])
def test_discover_requests(data, identity, obstacles):
    assert codec.decode_discover(data, IDENT, OT) == codec.DiscoverRequest(identity, obstacles)


@pytest.mark.parametrize("data", [{}, {"objectTypes": "x"}, {"objectTypes": []}, {"coreTypes": [1]},
                                  {"objectId": 5}, {"objectTypes": [OT], "coreTypes": ["Identity"]}])
def test_malformed_discovers_raise(data):
    with pytest.raises(InvalidPayloadError):
        codec.decode_discover(data, IDENT, OT)


def test_resolve_keeps_good_obstacles_next_to_bad_ones(make_update):
    good = wire(make_update())
    bad = dict(wire(make_update()), version="x")
    other = {"objectType": "org.other.Thing", "coreType": "CoatyObject", "objectId": IDENT, "name": "t"}
    content = codec.decode_resolve({"object": other, "relatedObjects": [bad, good, 5]}, OT)
    assert [u.uuid for u in content.obstacles] == [good["uuid"]]
    assert [type(e) for e in content.errors] == [WrongTypeError, WrongTypeError]
    with pytest.raises(MissingFieldError):
        codec.decode_resolve({"privateData": {}}, OT)


def test_identity_object_is_a_coaty_identity():
    assert codec.identity_object(IDENT.upper(), "robot_3") == {
        "objectType": "coaty.Identity", "coreType": "Identity", "objectId": IDENT, "name": "robot_3"}


def test_a_one_cell_rectangle_carrying_a_region_is_refused_before_its_cells_are_decoded(make_update):
    """The count of cells against the rectangle (issue 43, item 1) is what refuses the bomb *before expansion*:
    its compact string is longer than one cell can take, so it is not even base64-decoded. Every other check
    (cells outside the rectangle, and the count again after decoding) would refuse it only once all its cells are
    built. Its tail is made invalid base64 here: refused on the count, the reason says so; decoded first, the
    tail would be the reason (red with the codec's count check removed)."""
    from coaty_bridge.errors import RectangleCellsError
    region = tuple(880221 + dx + 2000 * dy for dx in range(40) for dy in range(40))
    bomb = make_update(rectangle=(1.05, 2.0, 1.1, 2.05), marked=region, cleared=())   # cell 880221's square
    obj = wire(bomb)
    assert isinstance(obj["markedIndexes"], str) and len(obj["markedIndexes"]) > 12   # one 5-byte varint's worth
    obj["markedIndexes"] = obj["markedIndexes"][:-4] + "!!!!"
    with pytest.raises(RectangleCellsError, match="more cells than its rectangle holds"):
        obstacle_from_object(obj, OT)
    obj["rectangle"] = [1.05, 2.0, 3.05, 4.0]          # the region's rectangle: now the tail is what is wrong
    with pytest.raises(WrongTypeError, match="not base64"):
        obstacle_from_object(obj, OT)
