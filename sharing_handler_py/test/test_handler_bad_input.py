"""Bad input is dropped with one log line naming source and reason, one counter, state untouched."""
import logging
import math

import pytest

from handler_fixtures import U, GRID, OTHER_GRID, Recorder, cells_in, proposal, rect, state, update
from sharing_handler_py.errors import InvalidMessageError, InvalidParameterError
from sharing_handler_py.logic import DROP_REASONS
from sharing_handler_py.validation import Geometry, HandlerParams, Obstacle, Rectangle


def _loaded():
    """A handler holding one own and one external obstacle."""
    r = Recorder(max_cells_per_message=1000)
    r.handler.on_proposal(proposal(cells=cells_in(rect(0, 0, 1, 1), 2), rectangle=rect(0, 0, 1, 1)))
    r.handler.on_external(update(U("ext-1"), marked=(5, 6), version=1, source="robot_1"))
    return r


BAD_EXTERNAL = [
    ("empty_uuid", dict(uuid="")),
    ("malformed", dict(uuid="has space")),
    ("malformed", dict(uuid="u" * 65)),
    ("malformed", dict(source="")),
    ("own_source", dict(source="robot_0")),
    ("bad_version", dict(version=0)),
    ("zero_deadline", dict(deadline=0)),
    ("too_many_cells", dict(marked=tuple(range(600)), cleared=tuple(range(600)))),
    ("index_out_of_range", dict(marked=(1, 400 * 200))),
    ("index_out_of_range", dict(cleared=(2 ** 32 - 1,))),
    # issue 15, failure 4: the handler is as strict as the bridge (sharing_msgs.obstacle_rules)
    ("malformed", dict(uuid="x")),
    ("bad_version", dict(version=2 ** 63)),
    ("bad_version", dict(version=2 ** 53)),
    ("empty_update", dict(marked=(), cleared=())),
    ("bad_stamp", dict(stamp=float(2 ** 32))),
    ("bad_stamp", dict(stamp=-1.0)),
    ("bad_stamp", dict(stamp=math.nan)),
    ("malformed", dict(deadline=2 ** 32)),
    ("rectangle_outside_grid", dict(rectangle=rect(-1e38, -1e38, 1e38, 1e38))),
    ("non_finite_rectangle", dict(rectangle=rect(-1e39, -5, -9, -4))),
    ("malformed", dict(source="robot/7")),
    ("geometry_mismatch", dict(geometry=OTHER_GRID)),
    ("geometry_mismatch", dict(geometry=Geometry(0.05, -10.0 + 1e-4, -5.0, 400, 200))),
    ("geometry_mismatch", dict(geometry=Geometry(0.05, -10.0, -5.0, 400, 201))),
]


@pytest.mark.parametrize("reason,changes", BAD_EXTERNAL, ids=[
    "%s-%s" % (r, "-".join(c)) for r, c in BAD_EXTERNAL])
def test_bad_external_message_is_dropped_logged_and_counted(reason, changes, caplog):
    r = _loaded()
    before, sent_layer, sent_fleet = state(r.handler), len(r.layer), len(r.fleet)
    fields = dict(uuid=U("ext-1"), marked=(7,), cleared=(5,), version=2, source="robot_7")
    fields.update(changes)
    with caplog.at_level(logging.DEBUG, logger="sharing_handler_py"):
        assert r.handler.on_external(update(**fields)) is False
    assert state(r.handler) == before
    assert (len(r.layer), len(r.fleet)) == (sent_layer, sent_fleet)
    counters = r.handler.counters
    assert counters["dropped_" + reason] == 1
    assert sum(v for k, v in counters.items() if k.startswith("dropped_")) == 1
    drops = [rec for rec in caplog.records if "dropped" in rec.getMessage()]
    assert len(drops) == 1 and drops[0].levelno == logging.WARNING
    assert repr(fields["source"]) in drops[0].getMessage() and reason in drops[0].getMessage()
    # the handler keeps working
    assert r.handler.on_external(update(U("ext-1"), marked=(8,), version=3, source="robot_7"))
    assert 8 in r.handler.get(U("ext-1")).cells


def test_geometry_within_tolerance_is_ours():
    r = _loaded()
    close = Geometry(0.05 * (1 + 5e-7), -10.0 * (1 + 5e-7), -5.0, 400, 200)
    assert r.handler.on_external(update(U("ext-2"), marked=(1,), version=1, geometry=close))
    # resolution travels as float32: 0.05 becomes 0.0500000007..., still the same grid
    import struct
    f32 = struct.unpack("f", struct.pack("f", 0.05))[0]
    assert GRID.matches(Geometry(f32, -10.0, -5.0, 400, 200))
    assert Geometry(0.05, 0.0, 0.0, 4, 4).matches(Geometry(0.05, 1e-12, -1e-12, 4, 4))


@pytest.mark.parametrize("build,reason", [
    (lambda: Rectangle(float("nan"), 0, 1, 1), "non_finite_rectangle"),
    (lambda: Rectangle(0, 0, float("inf"), 1), "non_finite_rectangle"),
    (lambda: Rectangle(2, 0, 1, 1), "malformed"),
    (lambda: Rectangle.from_sequence([0, 0, 1]), "malformed"),
    (lambda: Rectangle.from_sequence([]), "malformed"),
    (lambda: Geometry(0.0, 0, 0, 10, 10), "bad_geometry"),
    (lambda: Geometry(float("nan"), 0, 0, 10, 10), "bad_geometry"),
    (lambda: Geometry(0.05, math.inf, 0, 10, 10), "bad_geometry"),
    (lambda: Geometry(0.05, 0, 0, 0, 10), "bad_geometry"),
    (lambda: Geometry(0.05, 0, 0, 70000, 70000), "bad_geometry"),
    (lambda: Obstacle("u", (1,), (), -1, Rectangle(0, 0, 1, 1), "r", GRID), "malformed"),
    (lambda: Obstacle("u", (1,), (), 1, [0, 0, 1, 1], "r", GRID), "malformed"),
])
def test_value_types_refuse_bad_fields_with_the_bad_value(build, reason):
    with pytest.raises(InvalidMessageError) as info:
        build()
    assert info.value.reason == reason
    assert str(info.value).startswith(reason)


def test_reject_counts_unknown_reasons_as_malformed_and_names_the_source(caplog):
    r = Recorder()
    with caplog.at_level(logging.WARNING, logger="sharing_handler_py"):
        r.handler.reject("robot_3 (on from_fleet)", "u-1", InvalidMessageError("weird", "x"))
    assert r.handler.counters["dropped_malformed"] == 1
    assert "robot_3" in caplog.records[0].getMessage()


def test_every_drop_reason_has_a_zero_counter_from_the_start():
    counters = Recorder().handler.counters
    assert all(counters["dropped_" + reason] == 0 for reason in DROP_REASONS)


@pytest.mark.parametrize("changes,reason", [
    (dict(cells=()), "empty_proposal"),
    (dict(geometry=OTHER_GRID), "geometry_mismatch"),
    (dict(cells=(400 * 200,)), "index_out_of_range"),
])
def test_bad_proposal_is_dropped_and_counted(changes, reason):
    r = Recorder()
    assert r.handler.on_proposal(proposal(**changes)) is None
    assert r.handler.counters["dropped_" + reason] == 1
    assert len(r.handler) == 0 and r.fleet == [] and r.layer == []


def test_proposal_with_a_uuid_is_malformed():
    r = Recorder()
    assert r.handler.on_proposal(proposal().replace(uuid="abc")) is None
    assert r.handler.counters["dropped_malformed"] == 1


def test_internal_update_with_bad_grid_is_dropped_and_not_sent():
    r = Recorder()
    shared = r.handler.on_proposal(proposal())
    assert r.handler.on_internal_update(update(shared.uuid, marked=(1,), geometry=OTHER_GRID,
                                               source="robot_0")) is None
    assert r.handler.counters["dropped_geometry_mismatch"] == 1 and r.fleet == [shared]


# ---------------------------------------------------------------- parameters

@pytest.mark.parametrize("changes,name", [
    (dict(obstacle_duration=-5), "~obstacle_duration = -5"),
    (dict(obstacle_duration=0.5), "~obstacle_duration = 0.5"),
    (dict(obstacle_duration=float("nan")), "~obstacle_duration = nan"),
    (dict(obstacle_duration="60"), "~obstacle_duration = '60'"),
    (dict(expiry_rate=0), "~expiry_rate = 0"),
    (dict(expiry_rate=-1.0), "~expiry_rate = -1.0"),
    (dict(robot_name=""), "~robot_name = ''"),
    (dict(robot_name="fleet/robot_0"), "~robot_name = 'fleet/robot_0'"),
    (dict(max_cells_per_message=0), "~max_cells_per_message = 0"),
    (dict(max_cells_per_message=True), "~max_cells_per_message = True"),
    (dict(snapshot_file=None), "~snapshot_file = None"),
    (dict(merge_distance=-0.1), "~merge_distance = -0.1"),
    (dict(merge_distance=float("inf")), "~merge_distance = inf"),
    (dict(merge_distance="0.5"), "~merge_distance = '0.5'"),
])
def test_bad_parameters_fail_naming_parameter_and_value(changes, name):
    fields = dict(robot_name="robot_0")
    fields.update(changes)
    with pytest.raises(InvalidParameterError) as info:
        HandlerParams(**fields)
    assert str(info.value).startswith(name)


def test_parameter_defaults():
    p = HandlerParams(robot_name="robot_0")
    assert (p.obstacle_duration, p.expiry_rate, p.snapshot_file, p.max_cells_per_message, p.map_topic,
            p.merge_distance) == (1200.0, 1.0, "", 100000, "/map", 0.5)
