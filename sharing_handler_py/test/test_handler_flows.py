"""Every flow of the SharingHandler, through the pure module (no roscore)."""
import logging
import re

import pytest

from handler_fixtures import U, GRID, FakeClock, Recorder, cell_in, cells_in, proposal, rect, state, update
from sharing_handler_py.errors import InvalidRequestError
from sharing_handler_py.logic import SharingHandler

UUID4 = re.compile(r"^[0-9a-f]{8}-[0-9a-f]{4}-4[0-9a-f]{3}-[89ab][0-9a-f]{3}-[0-9a-f]{12}$")


# ---------------------------------------------------------------- proposals

def test_proposal_is_authorised_to_layer_then_fleet_with_uuid4_deadline_and_version_1():
    r = Recorder(duration=45)
    shared = r.handler.on_proposal(proposal(cells=(12, 10, 11)))
    assert UUID4.match(shared.uuid), shared.uuid
    assert (shared.version, shared.source, shared.deadline) == (1, "robot_0", 45)
    assert [kind for kind, _ in r.events] == ["layer", "fleet"]
    assert r.layer == [shared] and r.fleet == [shared]
    held = r.handler.get(shared.uuid)
    assert held.cells == (10, 11, 12)
    assert held.arrival == 100.0 and held.remaining == 45
    assert r.handler.counters["authorised"] == 1 and r.changes == 1


def test_fractional_duration_rounds_up_to_whole_seconds():
    r = Recorder(duration=2.5)
    assert r.handler.on_proposal(proposal()).deadline == 3


def test_overlapping_proposal_becomes_an_update_of_the_live_obstacle(caplog):
    """Issue 12, failure 4: a second trigger proposed a rectangle touching the first obstacle and
    it was authorised as a new one. Now it is an observation of that obstacle: an update with
    its uuid, the proposal's cells, the union rectangle and a renewed lease, sent to the fleet
    and to the layer (which does not know its proposal became an update)."""
    r = Recorder(duration=60)
    one, two, three = cell_in(rect(0, 0, 1, 1), 0), cell_in(rect(1, 1, 2, 2), 0), cell_in(rect(2, 2, 3, 3), 0)
    first = r.handler.on_proposal(proposal(cells=(one, two), rectangle=rect(0, 0, 2, 2)))
    r.clock.now += 20
    with caplog.at_level(logging.INFO, logger="sharing_handler_py"):
        merged = r.handler.on_proposal(proposal(cells=(two, three), rectangle=rect(1, 1, 3, 3)))
    assert (merged.uuid, merged.version, merged.source) == (first.uuid, 2, "robot_0")
    assert (merged.marked, merged.cleared, merged.deadline) == ((two, three), (), 60)
    assert merged.rectangle == rect(0, 0, 3, 3)
    assert r.fleet == [first, merged] and r.layer == [first, merged]
    held = r.handler.get(first.uuid)
    assert (held.cells, held.rectangle, held.remaining) == ((one, two, three), rect(0, 0, 3, 3), 60)
    assert len(r.handler) == 1
    assert r.handler.counters["merged_proposals"] == 1 and r.handler.counters["authorised"] == 1
    lines = [rec.getMessage() for rec in caplog.records if "merge_distance" in rec.getMessage()]
    assert len(lines) == 1 and first.uuid in lines[0]


def test_a_proposal_near_another_robots_obstacle_is_an_obstacle_of_its_own():
    """Issue 43, item 2: a proposal that became an update of another robot's obstacle showed this robot's
    cells under that robot's name and renewed its whole lease. Now it is this robot's own obstacle; near
    one of its own it is still an update of that one (above)."""
    r = Recorder()
    theirs, ours = cell_in(rect(0, 0, 2, 2), 0), cell_in(rect(2.3, 0, 4, 1), 0)
    r.handler.on_external(update(U("ext-1"), marked=(theirs,), version=1, rectangle=rect(0, 0, 2, 2)))
    r.clock.now += 20
    shared = r.handler.on_proposal(proposal(cells=(ours,), rectangle=rect(2.3, 0, 4, 1)))
    assert shared.uuid != U("ext-1") and (shared.version, shared.source) == (1, "robot_0")
    assert r.handler.get(U("ext-1")).cells == (theirs,) and r.handler.get(U("ext-1")).source == "robot_1"
    assert r.handler.get(U("ext-1")).remaining == pytest.approx(10.0), "not renewed by another robot's proposal"
    assert r.handler.get(shared.uuid).cells == (ours,)
    assert r.handler.counters["merged_proposals"] == 0


def test_a_proposal_beyond_merge_distance_is_a_new_obstacle():
    r = Recorder(merge_distance=0.5)
    first = r.handler.on_proposal(proposal(cells=cells_in(rect(0, 0, 1, 1), 3), rectangle=rect(0, 0, 1, 1)))
    second = r.handler.on_proposal(proposal(cells=cells_in(rect(1.6, 0, 2, 1), 3), rectangle=rect(1.6, 0, 2, 1)))
    assert second.uuid != first.uuid and second.version == 1
    assert len(r.handler) == 2
    # 0.5 m from both: it joins them into one, the smaller uuid (uuid4s: either may be smaller)
    third = proposal(cells=cells_in(rect(1, 1.5, 2, 2), 3), rectangle=rect(1, 1.5, 2, 2))
    assert r.handler.on_proposal(third).uuid == min(first.uuid, second.uuid)
    assert len(r.handler) == 1 and r.handler.counters["merged_obstacles"] == 1


def test_touching_rectangles_do_not_overlap_but_a_degenerate_one_inside_does():
    assert not rect(0, 0, 1, 1).overlaps(rect(1, 0, 2, 1))
    assert rect(0, 0, 1, 1).overlaps(rect(0.5, 0.5, 0.5, 0.5))
    assert rect(0, 0, 1, 1).overlaps(rect(1, 0.5, 1, 0.5))
    assert not rect(0, 0, 1, 1).overlaps(rect(1.01, 0.5, 1.01, 0.5))
    assert rect(0, 0, 1, 1).gap(rect(1, 0, 2, 1)) == 0.0
    assert rect(0, 0, 1, 1).gap(rect(1.5, 3, 2, 4)) == pytest.approx(2.0)
    assert rect(0, 0, 1, 1).union(rect(1.5, 3, 2, 4)) == rect(0, 0, 2, 4)


def test_first_proposal_sets_the_grid_when_no_map_has_arrived():
    r = Recorder(geometry=None)
    assert r.handler.geometry is None
    r.handler.on_proposal(proposal())
    assert r.handler.geometry == GRID


# ---------------------------------------------------------------- internal updates

def test_internal_update_is_sent_to_the_fleet_before_it_is_applied():
    r = Recorder()
    shared = r.handler.on_proposal(proposal(cells=(10, 11)))
    seen_at_send = []
    r.handler._to_fleet = lambda o: seen_at_send.append(r.handler.get(o.uuid).cells)
    sent = r.handler.on_internal_update(update(shared.uuid, marked=(19,), cleared=(10,), version=2,
                                               source="robot_0"))
    assert seen_at_send == [(10, 11)]
    assert sent.version == 2 and sent.source == "robot_0"
    assert r.handler.get(shared.uuid).cells == (11, 19)
    assert r.handler.get(shared.uuid).version == 2
    assert len(r.layer) == 1, "an internal update is not echoed to the layer"
    assert r.handler.counters["updates_out"] == 1


def test_internal_update_with_a_stale_version_is_restamped_above_the_max_seen(caplog):
    r = Recorder()
    shared = r.handler.on_proposal(proposal(cells=(10,)))
    r.handler.on_external(update(shared.uuid, marked=(15,), version=7, source="robot_1"))
    with caplog.at_level(logging.DEBUG, logger="sharing_handler_py"):
        sent = r.handler.on_internal_update(update(shared.uuid, marked=(18,), cleared=(15,),
                                                   version=3, source="robot_0"))
    assert sent.version == 8
    assert r.fleet[-1].version == 8
    assert r.handler.get(shared.uuid).cells == (10, 18)
    assert r.handler.counters["restamped"] == 1
    assert any("re-stamped 8" in rec.getMessage() for rec in caplog.records)


def test_internal_update_sends_the_grown_rectangle_and_renews_the_lease_when_it_marks():
    r = Recorder(duration=60)
    shared = r.handler.on_proposal(proposal(cells=cells_in(rect(0, 0, 1, 1), 3), rectangle=rect(0, 0, 1, 1)))
    r.clock.now += 40
    sent = r.handler.on_internal_update(update(shared.uuid, marked=(cell_in(rect(4, 4, 5, 5), 0),), version=2,
                                               source="robot_0", deadline=0, rectangle=rect(0, 0, 5, 5)))
    assert sent.rectangle == rect(0, 0, 5, 5) and sent.deadline == 60
    held = r.handler.get(shared.uuid)
    assert held.rectangle == rect(0, 0, 5, 5) and held.remaining == 60
    assert r.handler.counters["renewals"] == 1
    r.clock.now += 59
    assert r.handler.expire() == [], "renewed 40 s after the share: lives 60 s from then"
    r.clock.now += 1
    assert r.handler.expire() == [shared.uuid]


def test_internal_update_that_only_clears_carries_the_lifetime_left_when_it_is_sent():
    """A robot that missed the first share adds the obstacle from an update: it must not keep
    it longer than the robot that shared it (issue 15, item 2). Only cells seen occupied renew."""
    r = Recorder(duration=60)
    cells = cells_in(rect(0, 0, 1, 1), 3)
    shared = r.handler.on_proposal(proposal(cells=cells, rectangle=rect(0, 0, 1, 1)))
    r.clock.now += 25.4
    sent = r.handler.on_internal_update(update(shared.uuid, cleared=cells[:1], version=2, source="robot_0",
                                               deadline=60, rectangle=rect(0, 0, 1, 1)))
    assert sent.deadline == 34  # 34.6 s left, rounded down
    assert r.handler.counters["renewals"] == 0
    late = Recorder("robot_1", clock=r.clock)
    late.handler.on_external(sent)
    assert late.handler.get(shared.uuid).remaining <= r.handler.get(shared.uuid).remaining


def test_the_greatest_lease_wins_whatever_the_order():
    r = Recorder(duration=60)
    r.handler.on_external(update(U("a"), marked=(1,), version=1, deadline=30))   # expires at 130
    r.clock.now += 10
    r.handler.on_external(update(U("a"), marked=(2,), version=2, deadline=50))   # renewed: 160
    assert r.handler.get(U("a")).remaining == pytest.approx(50.0)
    r.handler.on_external(update(U("a"), marked=(3,), version=3, deadline=5))    # an old copy: 115
    assert r.handler.get(U("a")).remaining == pytest.approx(50.0)
    r.clock.now += 49.9
    assert r.handler.expire() == []
    r.clock.now += 0.1
    assert r.handler.expire() == [U("a")]


def test_internal_update_for_an_unknown_uuid_is_dropped():
    r = Recorder()
    assert r.handler.on_internal_update(update(U("nope"), marked=(1,), source="robot_0")) is None
    assert r.fleet == [] and r.handler.counters["dropped_unknown_uuid"] == 1


# ---------------------------------------------------------------- external messages

def test_external_unknown_uuid_is_added_with_its_deadline_and_local_arrival_and_not_echoed():
    r = Recorder(duration=60)
    r.clock.now = 250.0
    msg = update(U("ext-1"), marked=(3, 1, 2), version=1, source="robot_1", deadline=17)
    assert r.handler.on_external(msg) is True
    held = r.handler.get(U("ext-1"))
    assert (held.cells, held.deadline, held.arrival, held.source) == ((1, 2, 3), 17, 250.0, "robot_1")
    assert r.layer == [msg] and r.fleet == []
    assert r.handler.counters["updates_in"] == 1


def test_external_update_appends_marked_without_duplicates_then_removes_cleared():
    r = Recorder()
    r.handler.on_external(update(U("ext-1"), marked=(1, 2, 3), version=1, source="robot_1"))
    second = update(U("ext-1"), marked=(3, 4, 5, 5), cleared=(1, 5), version=2, source="robot_2")
    r.handler.on_external(second)
    assert r.handler.get(U("ext-1")).cells == (2, 3, 4)
    assert r.layer[-1] is second and r.fleet == []


def test_older_update_arriving_late_cannot_undo_a_newer_one():
    r = Recorder()
    r.handler.on_external(update(U("ext-1"), marked=(1,), version=1, source="robot_1"))
    r.handler.on_external(update(U("ext-1"), cleared=(1,), version=3, source="robot_2"))
    r.handler.on_external(update(U("ext-1"), marked=(1,), version=2, source="robot_1"))
    assert r.handler.get(U("ext-1")).cells == ()
    assert r.handler.get(U("ext-1")).version == 3


def test_the_first_share_defines_rectangle_deadline_and_source_even_when_it_arrives_late():
    r = Recorder()
    r.handler.on_external(update(U("ext-1"), marked=(cell_in(rect(8, 4, 9, 4.5), 0),), version=3, source="robot_2",
                                 deadline=90, rectangle=rect(0, 0, 9, 4.5)))
    r.handler.on_external(update(U("ext-1"), marked=(cell_in(rect(0, 0, 1, 1), 0),), version=1, source="robot_1",
                                 deadline=30, rectangle=rect(0, 0, 1, 1)))
    held = r.handler.get(U("ext-1"))
    assert (held.source, held.deadline, held.rectangle, held.version) == \
        ("robot_1", 30, rect(0, 0, 9, 4.5), 3), "the rectangle is the union of all seen"


def test_fleet_messages_wait_for_the_grid_and_are_applied_when_the_map_arrives():
    r = Recorder(geometry=None)
    assert r.handler.on_external(update(U("ext-1"), marked=(1,), version=1)) is False
    assert r.handler.counters["deferred"] == 1 and len(r.handler) == 0
    r.handler.set_geometry(GRID)
    assert r.handler.get(U("ext-1")).cells == (1,)
    assert len(r.layer) == 1


def test_waiting_queue_is_bounded():
    r = Recorder(geometry=None, max_deferred=2)
    for i in range(3):
        r.handler.on_external(update(U("ext-%d" % i), marked=(cell_in(rect(3 * i, 0, 3 * i + 1, 1), 0),), version=1,
                                     rectangle=rect(3 * i, 0, 3 * i + 1, 1)))
    assert r.handler.counters["dropped_no_geometry"] == 1
    r.handler.set_geometry(GRID)
    assert [h.uuid for h in r.handler.obstacles()] == [U("ext-0"), U("ext-1")]


# ---------------------------------------------------------------- expiry

def test_obstacle_expires_exactly_at_deadline_after_local_arrival_without_any_fleet_message():
    r = Recorder(duration=10)
    shared = r.handler.on_proposal(proposal())
    r.clock.now = 100.0 + 9.999
    assert r.handler.expire() == []
    r.clock.now = 110.0
    changes = r.changes
    assert r.handler.expire() == [shared.uuid]
    assert r.expired == [shared.uuid] and len(r.handler) == 0
    assert r.fleet == [shared], "expiry sends nothing to the fleet"
    assert r.handler.counters["expired"] == 1 and r.changes == changes + 1


def test_external_obstacle_expires_by_its_own_deadline_counted_from_local_arrival():
    r = Recorder(duration=60)
    r.clock.now = 500.0
    r.handler.on_external(update(U("ext-1"), marked=(1,), version=1, deadline=5))
    r.clock.now = 504.0
    assert r.handler.expire() == []
    r.clock.now = 505.0
    assert r.handler.expire() == [U("ext-1")]


def test_late_message_for_an_expired_obstacle_does_not_resurrect_it_until_the_tombstone_ends():
    r = Recorder(duration=60)
    r.handler.on_external(update(U("ext-1"), marked=(1,), version=1, deadline=5))
    r.clock.now += 5
    r.handler.expire()
    assert r.handler.on_external(update(U("ext-1"), marked=(2,), version=2)) is False
    assert len(r.handler) == 0 and r.handler.counters["dropped_expired"] == 1
    assert r.handler.is_tombstoned(U("ext-1"))
    r.clock.now += 59.9
    r.handler.expire()
    assert r.handler.is_tombstoned(U("ext-1")), "remembered for at least obstacle_duration"
    r.clock.now += 0.1
    r.handler.expire()
    assert not r.handler.is_tombstoned(U("ext-1"))


def test_an_internal_update_that_only_clears_an_expired_obstacle_is_dropped():
    r = Recorder(duration=1)
    shared = r.handler.on_proposal(proposal())
    r.clock.now += 1
    r.handler.expire()
    assert r.handler.on_internal_update(update(shared.uuid, cleared=(10,), source="robot_0")) is None
    assert r.handler.counters["dropped_expired"] == 1 and len(r.fleet) == 1


def test_a_robot_that_sees_an_expired_obstacle_again_shares_it_again_under_a_new_uuid():
    """Issue 43, item 3: an obstacle's tombstone stopped the robot that still saw it from sharing it again
    (nothing came back in 90 s). Its layer marking cells of the expired uuid makes a new obstacle of them."""
    r = Recorder(duration=1)
    shared = r.handler.on_proposal(proposal())
    r.clock.now += 1
    r.handler.expire()
    again = r.handler.on_internal_update(update(shared.uuid, marked=(11, 12), cleared=(10,), source="robot_0"))
    assert again is not None and again.uuid != shared.uuid and again.version == 1
    assert (again.marked, again.cleared, again.source) == ((11, 12), (), "robot_0")
    assert r.fleet[-1] == again and r.layer[-1] == again
    assert r.expired[-1] == shared.uuid, "the layer drops the expired uuid for the new one"
    assert r.handler.get(again.uuid).cells == (11, 12)
    assert r.handler.counters["reshared"] == 1 and r.handler.counters["dropped_expired"] == 0



@pytest.mark.parametrize("left,reshared", [(0.9, True), (1.0, False)])
def test_a_robot_that_sees_an_obstacle_in_its_last_second_shares_it_again_before_the_tick(left, reshared):
    """The same when the layer's mark comes while the lease has less than 1 s left and the expiry tick has not
    run yet (the node test of issue 43, item 3 met this race: the mark was dropped as expired, for good)."""
    r = Recorder(duration=10)
    shared = r.handler.on_proposal(proposal())
    r.clock.now += 10 - left
    again = r.handler.on_internal_update(update(shared.uuid, marked=(11, 12), source="robot_0"))
    if reshared:
        assert again is not None and again.uuid != shared.uuid and again.version == 1
        assert not r.handler.get(shared.uuid) and r.handler.is_tombstoned(shared.uuid)
        assert r.expired[-1] == shared.uuid and r.handler.counters["expired"] == 1
        assert r.handler.counters["reshared"] == 1 and r.handler.counters["dropped_expired"] == 0
    else:                           # a whole second left: an update of the obstacle as it is
        assert again is not None and again.uuid == shared.uuid
        assert r.handler.counters["reshared"] == 0 and r.handler.counters["expired"] == 0


# ---------------------------------------------------------------- manual add and list

def test_manual_add_fills_the_rectangle_and_is_shared_like_a_detection():
    r = Recorder(duration=60)
    shared = r.handler.add_manual([-10.0, -5.0, -9.9, -4.95])   # 2 x 1 cells at the grid corner
    assert shared.marked == (0, 1) and shared.deadline == 60 and shared.version == 1
    assert r.layer == [shared] and r.fleet == [shared]
    assert r.handler.counters["manual"] == 1


def test_manual_add_with_cells_and_deadline():
    r = Recorder()
    cells = cells_in(rect(0, 0, 1, 1), 2)
    shared = r.handler.add_manual([0, 0, 1, 1], marked=cells, deadline=12)
    assert (shared.marked, shared.deadline) == (cells, 12)


@pytest.mark.parametrize("kwargs,why", [
    (dict(rectangle=[100, 100, 101, 101]), "not inside the grid"),
    (dict(rectangle=[-1e38, -1e38, 1e38, 1e38]), "not inside the grid"),      # failure 3 of issue 15
    (dict(rectangle=[-1e39, -1e39, -9, -4]), "non_finite_rectangle"),       # not even a float32
    (dict(rectangle=[-10, -5, 10, 5]), "max_obstacle_extent"),             # the whole 20 m x 10 m map
    (dict(rectangle=[0.001, 0.001, 0.002, 0.002]), "covers no cell"),
    (dict(rectangle=[0, 0, 1, 1], deadline=2 ** 32), "deadline"),
    (dict(rectangle=[0, 0, 1]), "4"),
    (dict(rectangle=[0, 0, 1, 1], marked=(400 * 200,)), "index_out_of_range"),
])
def test_manual_add_refusals_say_why(kwargs, why):
    r = Recorder()
    r.handler.on_proposal(proposal(rectangle=rect(-10, -5, -9, -4)))
    with pytest.raises(InvalidRequestError, match=why):
        r.handler.add_manual(**kwargs)
    assert len(r.handler) == 1


def test_manual_add_near_a_live_obstacle_updates_it():
    r = Recorder()
    shared = r.handler.on_proposal(proposal(rectangle=rect(-10, -5, -9, -4)))
    merged = r.handler.add_manual([-9.2, -5, -8, -4])
    assert merged.uuid == shared.uuid and merged.version == 2 and len(r.handler) == 1
    assert r.handler.get(shared.uuid).rectangle == rect(-10, -5, -8, -4)


def test_manual_add_is_stamped_with_the_time_it_was_made():
    r = Recorder()
    r.clock.now = 1234.5
    shared = r.handler.add_manual([0, 0, 1, 1])
    assert shared.stamp == 1234.5 and r.fleet[-1].stamp == 1234.5


def test_manual_add_within_max_obstacle_extent_is_accepted():
    r = Recorder(max_obstacle_extent=20.0)
    assert r.handler.add_manual([-10, -5, 10, 5]).marked


def test_manual_add_without_a_grid_is_refused():
    with pytest.raises(InvalidRequestError, match="no map"):
        Recorder(geometry=None).handler.add_manual([0, 0, 1, 1])


def test_list_holds_full_state_sorted_by_uuid_with_remaining_time():
    r = Recorder(duration=60)
    r.handler.on_external(update(U("b"), marked=(cell_in(rect(5, 0, 6, 1), 0),), version=4, deadline=30,
                                 source="robot_2", rectangle=rect(5, 0, 6, 1)))
    r.handler.on_external(update(U("a"), marked=(5, 1), cleared=(9,), version=1, deadline=10,
                                 source="robot_1"))
    r.clock.now += 2.5
    held = r.handler.obstacles()
    assert [h.uuid for h in held] == [U("a"), U("b")]
    full = held[0].to_obstacle()
    assert (full.marked, full.cleared, full.deadline, full.version, full.source) == \
        ((1, 5), (), 7, 1, "robot_1")  # 7.5 s left: rounded down, a copy must not outlive it
    assert held[0].remaining == pytest.approx(7.5)


def test_list_deadline_is_at_least_one_second():
    r = Recorder()
    r.handler.on_external(update(U("a"), marked=(1,), version=1, deadline=3))
    r.clock.now += 2.99999
    assert r.handler.obstacles()[0].to_obstacle().deadline == 1


def test_handler_rejects_bad_construction_arguments():
    with pytest.raises(ValueError, match="obstacle_duration"):
        SharingHandler("robot_0", FakeClock(), -1, print, print, print)
    with pytest.raises(ValueError, match="robot_name"):
        SharingHandler("", FakeClock(), 60, print, print, print)


def test_same_messages_same_state_and_duplicates_change_nothing():
    a, b = Recorder("observer_a"), Recorder("observer_b")
    msgs = [update(U("x"), marked=(1, 2), version=1, source="robot_1"),
            update(U("x"), marked=(3,), cleared=(1,), version=2, source="robot_2")]
    for m in msgs + msgs:
        a.handler.on_external(m)
    changes = a.changes
    for m in msgs:
        a.handler.on_external(m)
    assert a.changes == changes
    for m in reversed(msgs):
        b.handler.on_external(m)
    assert state(a.handler) == state(b.handler)


def test_after_a_restart_own_obstacles_are_accepted_back_from_peers_but_echoes_of_held_ones_are_not():
    r = Recorder("robot_0")
    mine = update(U("mine"), marked=(3,), version=2, source="robot_0")
    assert r.handler.on_external(mine)                    # not held: a peer gives it back
    assert r.handler.get(U("mine")).cells == (3,)
    assert r.handler.on_external(mine.replace(version=3, marked=(4,))) is False  # held: an echo
    assert r.handler.counters["dropped_own_source"] == 1


def test_an_update_that_clears_the_last_cell_removes_the_obstacle_on_the_sender_and_every_receiver():
    """Issue 26: evidence ends an obstacle at once, not its lease; the layer gets the clearing update
    (its copy has no cell left to draw) and nobody lists the obstacle any more."""
    a, b = Recorder("robot_0", duration=1200), Recorder("robot_1", duration=1200)
    c10, c11, c12 = cells_in(rect(0, 0, 1, 1), 3)
    shared = a.handler.on_proposal(proposal(cells=(c10, c11, c12), rectangle=rect(0, 0, 1, 1)))
    b.handler.on_external(shared)
    part = a.handler.on_internal_update(update(shared.uuid, cleared=(c10, c11), version=2, source="robot_0",
                                               rectangle=rect(0, 0, 1, 1)))
    b.handler.on_external(part)
    assert [h.cells for h in a.handler.obstacles()] == [h.cells for h in b.handler.obstacles()] == [(c12,)]
    last = a.handler.on_internal_update(update(shared.uuid, cleared=(c12,), version=3, source="robot_0",
                                               rectangle=rect(0, 0, 1, 1)))
    assert last is not None and last.cleared == (c12,)      # it still goes out, so the fleet clears it too
    b.handler.on_external(last)
    # the receiver's layer gets the clearing update (the sender's layer made it)
    assert b.layer[-1].uuid == shared.uuid and b.layer[-1].cleared == (c12,)
    for r in (a, b):
        assert r.handler.obstacles() == []
        assert r.handler.counters["cleared_by_evidence"] == 1
        assert r.handler.get(shared.uuid).cells == ()       # its stamps stay until the lease ends
        assert r.expired == []                              # no expiry: nothing else to tell the layer


def test_a_newer_mark_shows_a_cleared_obstacle_again_and_an_older_one_does_not():
    r = Recorder(duration=1200)
    r.handler.on_external(update(U("a"), marked=(1, 2), version=1, source="robot_1"))
    r.handler.on_external(update(U("a"), cleared=(1, 2), version=3, source="robot_2"))
    assert r.handler.obstacles() == []
    r.handler.on_external(update(U("a"), marked=(2,), version=2, source="robot_1"))   # older: stays cleared
    assert r.handler.obstacles() == []
    r.handler.on_external(update(U("a"), marked=(2,), version=4, source="robot_1"))   # the block is back
    assert [(h.uuid, h.cells) for h in r.handler.obstacles()] == [(U("a"), (2,))]
    assert r.handler.counters["cleared_by_evidence"] == 1


def test_remove_by_hand_clears_every_cell_fleet_wide_and_says_who_asked(caplog):
    """Issue 28: remove_obstacle. The removal is this robot's update clearing every present cell: the
    fleet applies it like evidence, so every robot drops the obstacle; this robot's layer is told too."""
    a, b = Recorder("robot_0", duration=1200), Recorder("robot_1", duration=1200)
    cells = cells_in(rect(0, 0, 1, 1), 3)
    first = a.handler.on_proposal(proposal(cells=cells, rectangle=rect(0, 0, 1, 1)))
    other = a.handler.on_proposal(proposal(cells=cells_in(rect(3, 3, 4, 4), 1), rectangle=rect(3, 3, 4, 4)))
    for m in (first, other):
        b.handler.on_external(m)
    with caplog.at_level("INFO"):
        removed = b.handler.remove(uuid=first.uuid, requested_by="operator anna")
    assert removed == [first.uuid]
    assert "requested by operator anna" in caplog.text
    out = b.fleet[-1]
    assert (out.uuid, out.source, out.marked, set(out.cleared)) == (first.uuid, "robot_1", (), set(cells))
    assert b.layer[-1] == out                     # b's own layer draws it no more
    a.handler.on_external(out)
    for r in (a, b):
        assert [h.uuid for h in r.handler.obstacles()] == [other.uuid]
    # by rectangle: every listed obstacle that meets it
    assert b.handler.remove(rectangle=[2.5, 2.5, 3.1, 3.1], requested_by="tool") == [other.uuid]
    assert b.handler.obstacles() == []


@pytest.mark.parametrize("kwargs, reason", [
    (dict(uuid=U("nope"), requested_by="x"), "no obstacle"),
    (dict(rectangle=[9, 9, 10, 10], requested_by="x"), "no listed obstacle meets"),
    (dict(rectangle=[1, 1, 0, 0], requested_by="x"), "give a uuid or a rectangle"),
    (dict(rectangle="everything", requested_by="x"), "give a uuid or a rectangle"),
    (dict(uuid=U("a"), requested_by=" "), "requested_by"),
])
def test_a_removal_that_cannot_be_done_says_why_and_changes_nothing(kwargs, reason):
    from sharing_handler_py.errors import InvalidRequestError
    r = Recorder(duration=1200)
    r.handler.on_external(update(U("a"), marked=cells_in(rect(0, 0, 1, 1), 1), version=1, source="robot_1",
                                 rectangle=rect(0, 0, 1, 1)))
    before = (r.handler.obstacles(), list(r.fleet), list(r.layer))
    with pytest.raises(InvalidRequestError, match=reason):
        r.handler.remove(**kwargs)
    assert (r.handler.obstacles(), list(r.fleet), list(r.layer)) == before
