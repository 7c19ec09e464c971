"""Bounded authority of a peer (issue 27, items 1, 2, 7, 8): whatever a message says, the receiving
handler's own caps bound the obstacle's extent, cells, lifetime, version and stamp. Pure; the same
attacks through a real mosquitto and real bridges are in coaty_bridge/test/test_peer_authority.py."""
import logging

import pytest

from handler_fixtures import U, GRID, Recorder, cell_in, cells_in, proposal, rect, state, update
from sharing_handler_py.errors import InvalidRequestError
from sharing_msgs import obstacle_rules
from sharing_msgs.authority import MIN_VERSION_STEP, OPERATOR_VERSION_MARGIN

WHOLE_MAP = rect(-10, -5, 10, 5)   # GRID is 20 m x 10 m


def _loaded(**kwargs):
    """robot_0 holding one own and one external obstacle, 10.6 m apart."""
    r = Recorder(max_cells_per_message=100000, **kwargs)
    r.handler.on_proposal(proposal(cells=cells_in(rect(-9, -4, -8.5, -3.5), 2), rectangle=rect(-9, -4, -8.5, -3.5)))
    r.handler.on_external(update(U("good"), marked=cells_in(rect(1.6, -4, 2.1, -3.5), 2), version=1, source="robot_1",
                                 rectangle=rect(1.6, -4, 2.1, -3.5), stamp=r.clock.now))
    return r


def _dropped_once(r, reason, caplog, value_text):
    counters = r.handler.counters
    assert counters["dropped_" + reason] == 1, counters
    assert sum(v for k, v in counters.items() if k.startswith("dropped_")) == 1, counters
    drops = [rec.getMessage() for rec in caplog.records if "dropped" in rec.getMessage()]
    assert len(drops) == 1 and reason in drops[0] and value_text in drops[0], drops
    assert "robot_9" in drops[0] and U("evil") in drops[0]   # the robot and the obstacle are named


def _still_works(r):
    """A fresh valid obstacle is taken, and the good ones are as they were."""
    assert r.handler.on_external(update(U("fresh"), marked=cells_in(rect(2, 2, 2.5, 2.5), 1), version=1,
                                        source="robot_1",
                                        rectangle=rect(2, 2, 2.5, 2.5), stamp=r.clock.now))
    assert U("fresh") in r.handler


@pytest.mark.parametrize("what,fields,reason,value_text", [
    ("whole-map rectangle", dict(rectangle=WHOLE_MAP), "oversized_rectangle", "20 m x 10 m"),
    ("version 2^53-1", dict(version=obstacle_rules.MAX_VERSION), "implausible_version",
     str(obstacle_rules.MAX_VERSION)),
    ("more cells than a 10 m square", dict(marked=tuple(range(45000))), "too_many_obstacle_cells", "45000"),
])
def test_a_peer_obstacle_beyond_the_caps_is_dropped_counted_and_named(what, fields, reason, value_text, caplog):
    r = _loaded()
    before = state(r.handler)
    values = dict(marked=cells_in(rect(0, 0, 1, 1), 1), version=1, source="robot_9", rectangle=rect(0, 0, 1, 1),
                  stamp=r.clock.now)
    values.update(fields)
    with caplog.at_level(logging.INFO, logger="sharing_handler_py"):
        assert r.handler.on_external(update(U("evil"), **values)) is False, what
    assert state(r.handler) == before
    _dropped_once(r, reason, caplog, value_text)
    _still_works(r)
    assert [h for h in state(r.handler) if h[0] != U("fresh")] == before


def test_a_version_far_beyond_the_highest_seen_is_dropped_a_step_within_is_taken():
    r = Recorder(max_version_step=MIN_VERSION_STEP)
    assert r.handler.on_external(update(U("a"), marked=(1,), version=5, stamp=r.clock.now))
    assert not r.handler.on_external(update(U("a"), marked=(2,), version=5 + MIN_VERSION_STEP + 1, stamp=r.clock.now))
    assert r.handler.counters["dropped_implausible_version"] == 1
    assert r.handler.on_external(update(U("a"), marked=(2,), version=5 + MIN_VERSION_STEP, stamp=r.clock.now))
    assert r.handler.get(U("a")).version == 5 + MIN_VERSION_STEP


def test_an_operators_removal_is_taken_at_the_least_step_by_a_robot_a_margin_behind_the_page():
    """The console sends the highest version its page heard + OPERATOR_VERSION_MARGIN; a robot that missed up to
    a margin of versions (partitioned) still takes it, at the least max_version_step a handler accepts."""
    r = Recorder(max_version_step=MIN_VERSION_STEP)
    assert r.handler.on_external(update(U("a"), marked=(1, 2), version=3, stamp=r.clock.now))
    heard_by_page = 3 + OPERATOR_VERSION_MARGIN       # versions this robot never got
    assert r.handler.on_external(update(U("a"), source="anna", marked=(), cleared=(1, 2),
                                        version=heard_by_page + OPERATOR_VERSION_MARGIN, stamp=r.clock.now))
    assert r.handler.counters.get("dropped_implausible_version", 0) == 0
    held = r.handler.get(U("a"))
    assert held is None or not held.cells, "the operator's removal left cells: %r" % (held,)


def test_the_proposal_path_is_capped_too():
    """obstacle_proposals is a ROS topic any node can publish on: a whole-map proposal is refused."""
    r = Recorder()
    assert r.handler.on_proposal(proposal(cells=(1,), rectangle=WHOLE_MAP)) is None
    assert r.handler.counters["dropped_oversized_rectangle"] == 1 and len(r.handler) == 0
    assert r.handler.on_proposal(proposal(cells=(1,), rectangle=rect(-10, -5, -9, -4))) is not None


def test_a_merge_never_makes_an_obstacle_larger_than_the_caps(caplog):
    """An attacker's 10 m obstacle (within the cap) beside good ones: without the merge cap the
    smaller uuid absorbs them all into something 11+ m long (issue 27: 20 obstacles became 1). Its
    own smaller obstacles beside it are not absorbed beyond the cap; other robots' never merge with it
    (issue 43, test below)."""
    r = _loaded()
    before = state(r.handler)
    evil = update(U("0evil"), marked=cells_in(rect(-8.7, -4, 1.3, 4), 1), version=1, source="robot_9",
                  rectangle=rect(-8.7, -4, 1.3, 4), stamp=r.clock.now)
    beside = [update(U("1evil-%d" % i), marked=cells_in(area, 1), version=1, source="robot_9", rectangle=area,
                     stamp=r.clock.now) for i, area in enumerate((rect(1.6, 0, 2.1, 0.5), rect(-9.4, 0, -9.0, 0.5)))]
    with caplog.at_level(logging.WARNING, logger="sharing_handler_py"):
        for message in [evil] + beside:
            assert r.handler.on_external(message)
    held = {h.uuid: h for h in r.handler.obstacles()}
    assert U("0evil") in held and held[U("0evil")].rectangle == evil.rectangle
    assert all(m.uuid in held for m in beside)
    assert [h for h in state(r.handler) if h[0] in (U("good"),)] == [h for h in before if h[0] == U("good")]
    assert r.handler.counters["merges_refused"] >= 2 and r.handler.counters["merged_obstacles"] == 0
    assert any("not merged" in rec.getMessage() and U("0evil") in rec.getMessage() for rec in caplog.records)
    # and a proposal beside it is not swallowed either: it becomes an obstacle of its own
    shared = r.handler.on_proposal(proposal(cells=cells_in(rect(1.5, 0, 2, 0.5), 1), rectangle=rect(1.5, 0, 2, 0.5)))
    assert shared.uuid not in (U("0evil"),) and shared.version == 1
    assert max(h.rectangle.max_x - h.rectangle.min_x for h in r.handler.obstacles()) <= 10.0


def test_merging_below_the_caps_still_happens():
    r = Recorder()
    r.handler.on_external(update(U("a"), marked=cells_in(rect(0, 0, 1, 1), 1), version=1, rectangle=rect(0, 0, 1, 1),
                                 stamp=r.clock.now))
    r.handler.on_external(update(U("b"), marked=cells_in(rect(1.2, 0, 2, 1), 1), version=1,
                                 rectangle=rect(1.2, 0, 2, 1), stamp=r.clock.now))
    assert len(r.handler) == 1 and r.handler.counters["merged_obstacles"] == 1


def test_add_obstacle_never_returns_none_when_the_update_it_becomes_is_refused():
    """The crash of issue 27: add_manual returned None ('NoneType' object has no attribute 'uuid')
    when the obstacle it merges into is at the last version."""
    r = Recorder(max_version_step=obstacle_rules.MAX_VERSION)
    cells = cells_in(rect(0, 0, 1, 1), 2)
    top = r.handler.on_proposal(proposal(cells=cells[:1], rectangle=rect(0, 0, 1, 1)))
    r.handler.on_internal_update(update(top.uuid, marked=cells[1:], version=obstacle_rules.MAX_VERSION,
                                        source="robot_0", rectangle=rect(0, 0, 1, 1), stamp=r.clock.now))
    with pytest.raises(InvalidRequestError, match="refused"):
        r.handler.add_manual([0.5, 0.5, 1.5, 1.5])
    assert r.handler.counters["dropped_bad_version"] == 1
    assert r.handler.add_manual([5, 2, 6, 3]).uuid   # elsewhere it still works


# ----------------------------------------------------------------------------- leases (item 2)

def test_a_huge_deadline_is_cut_to_our_obstacle_duration():
    r = Recorder(duration=60)
    assert r.handler.on_external(update(U("a"), marked=(1,), version=1, deadline=obstacle_rules.MAX_UINT32,
                                        stamp=r.clock.now))
    held = r.handler.get(U("a"))
    assert held.remaining == pytest.approx(60.0) and held.deadline == 60
    assert r.handler.counters["capped_deadlines"] == 1
    # a renewal (cells seen occupied) is capped as well
    r.clock.now += 30
    assert r.handler.on_external(update(U("a"), marked=(1,), version=2, deadline=obstacle_rules.MAX_UINT32,
                                        stamp=r.clock.now))
    assert r.handler.get(U("a")).remaining == pytest.approx(60.0)
    r.clock.now += 60
    assert r.handler.expire() == [U("a")]


def test_a_message_that_does_not_mark_cells_never_changes_the_lease():
    """Only an observation renews, and a clear never shortens the lease of the rest (issue 43, item 3: one
    cleared cell with deadline 1 shortened a real block's lease to 1 s, and it was gone fleet-wide)."""
    r = Recorder(duration=60)
    r.handler.on_external(update(U("a"), marked=(1, 2), version=1, deadline=30, stamp=r.clock.now))  # 130
    r.clock.now += 10
    assert r.handler.on_external(update(U("a"), cleared=(7,), version=2, deadline=60, stamp=r.clock.now))
    assert r.handler.get(U("a")).remaining == pytest.approx(20.0), "a clear must not extend the lease"
    assert r.handler.on_external(update(U("a"), cleared=(1,), version=3, deadline=1, stamp=r.clock.now))
    assert r.handler.get(U("a")).remaining == pytest.approx(20.0), "a clear must not shorten the lease"
    assert r.handler.get(U("a")).cells == (2,), "the cell it saw free is gone, the rest stays"
    assert r.handler.counters["clears_kept_lease"] == 2
    r.clock.now += 19.9
    assert r.handler.expire() == []
    r.clock.now += 0.1
    assert r.handler.expire() == [U("a")]


def test_a_copy_restoring_state_adds_an_obstacle_but_never_renews_one():
    """Discover answers are no observation (issue 43, item 4: re-marks pinned obstacles): on_state adds what
    is not held, with the copy's deadline, and never pushes a held obstacle's expiry back."""
    r = Recorder(duration=60)
    assert r.handler.on_state(update(U("a"), marked=(1,), version=1, deadline=30, stamp=r.clock.now))
    assert r.handler.get(U("a")).remaining == pytest.approx(30.0)
    r.clock.now += 10
    assert r.handler.on_state(update(U("a"), marked=(2,), version=2, deadline=60, stamp=r.clock.now))
    assert r.handler.get(U("a")).remaining == pytest.approx(20.0) and r.handler.get(U("a")).cells == (1, 2)
    assert r.handler.on_external(update(U("a"), marked=(3,), version=3, deadline=60, stamp=r.clock.now))
    assert r.handler.get(U("a")).remaining == pytest.approx(60.0), "a live observation does renew"
    assert r.handler.counters["state_copies"] == 2


# ----------------------------------------------------------------------------- replay (item 7)

def test_a_replayed_message_of_an_expired_obstacle_does_not_bring_it_back():
    r = Recorder(duration=60, max_clock_skew=5.0)
    captured = update(U("a"), marked=(1,), version=1, deadline=60, stamp=r.clock.now)
    assert r.handler.on_external(captured)
    r.clock.now += 60
    assert r.handler.expire() == [U("a")]
    r.clock.now += 10                               # remembered as expired: dropped as before
    assert not r.handler.on_external(captured)
    assert r.handler.counters["dropped_expired"] == 1
    r.clock.now += 61                               # long after; the tombstone is gone
    r.handler.expire()
    assert not r.handler.is_tombstoned(U("a"))
    assert not r.handler.on_external(captured)
    assert U("a") not in r.handler and r.handler.counters["dropped_stale_stamp"] == 1
    fresh = update(U("b"), marked=(1,), version=1, deadline=60, stamp=r.clock.now)
    assert r.handler.on_external(fresh) and U("b") in r.handler


def test_stamps_far_in_the_future_are_dropped_and_small_skews_are_taken(caplog):
    r = Recorder(duration=60, max_clock_skew=5.0)
    with caplog.at_level(logging.WARNING, logger="sharing_handler_py"):
        assert not r.handler.on_external(update(U("a"), marked=(1,), version=1, stamp=r.clock.now + 3600))
    assert r.handler.counters["dropped_future_stamp"] == 1
    assert "future_stamp" in caplog.text and "3600.0 s ahead" in caplog.text
    assert r.handler.on_external(update(U("b"), marked=(1,), version=1, stamp=r.clock.now + 4.9))
    assert r.handler.on_external(update(U("c"), marked=(2,), version=1, stamp=r.clock.now - 64.9))


def test_tombstones_outlast_the_stamp_window():
    """With stamps checked, an expired uuid is remembered until no message for it can pass the
    stamp check any more: obstacle_duration + 2 x max_clock_skew."""
    r = Recorder(duration=60, max_clock_skew=5.0)
    r.handler.on_external(update(U("a"), marked=(1,), version=1, deadline=60, stamp=r.clock.now))
    r.clock.now += 60
    r.handler.expire()
    r.clock.now += 69.9
    r.handler.expire()
    assert r.handler.is_tombstoned(U("a"))


# ------------------------------------------------------------------------- surrogates (item 8)

@pytest.mark.parametrize("field", ["source", "frame_id"])
def test_a_lone_surrogate_is_refused_at_validation_with_a_clear_error(field, caplog):
    r = _loaded()
    before = state(r.handler)
    bad = update(U("evil"), marked=(10,), version=1, source="robot_9", stamp=r.clock.now)
    bad = bad.replace(**{field: (bad.source if field == "source" else "map") + "\ud800"})
    with caplog.at_level(logging.WARNING, logger="sharing_handler_py"):
        assert r.handler.on_external(bad) is False
    assert state(r.handler) == before and r.handler.counters["dropped_malformed"] == 1
    assert "lone UTF-16 surrogate U+D800" in caplog.text
    caplog.text.encode("utf-8")   # the log line itself is valid text
    _still_works(r)


# ----------------------------------------------------------------------------- parameters

@pytest.mark.parametrize("changes,text", [
    (dict(max_obstacle_cells=-1), "~max_obstacle_cells = -1"),
    (dict(max_version_step=0), "~max_version_step = 0"),
    (dict(max_version_step=MIN_VERSION_STEP - 1), "~max_version_step = %d: must be an integer >= %d"
                                                   % (MIN_VERSION_STEP - 1, MIN_VERSION_STEP)),
    (dict(max_clock_skew=-2), "~max_clock_skew = -2"),
    (dict(max_clock_skew=float("nan")), "~max_clock_skew = nan"),
])
def test_bad_authority_parameters_fail_naming_parameter_and_value(changes, text):
    from sharing_handler_py.errors import InvalidParameterError
    from sharing_handler_py.validation import HandlerParams
    with pytest.raises(InvalidParameterError, match=text.replace(".", r"\.")):
        HandlerParams(robot_name="robot_0", **changes)


def test_authority_parameter_defaults_check_stamps_and_minus_one_turns_them_off():
    from sharing_handler_py.validation import HandlerParams
    params = HandlerParams(robot_name="robot_0")
    assert (params.max_obstacle_extent, params.max_obstacle_cells, params.max_version_step,
            params.clock_skew) == (10.0, 0, 1000000, 5.0)
    assert HandlerParams(robot_name="robot_0", max_clock_skew=-1).clock_skew is None
    r = Recorder()
    assert r.handler._policy.cell_cap(GRID) == 202 * 202
