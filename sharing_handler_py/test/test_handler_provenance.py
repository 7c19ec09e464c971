"""Issue 43, in the handler (pure): a message's cells lie inside its rectangle, a robot's obstacle is at most
what one robot can see, a merge keeps who said what, a clear never shortens a lease, a tombstone never stops
a robot that sees the obstacle again. The same through real mosquitto, bridges and handler nodes is in
coaty_bridge/test/test_attacks_43_nodes.py."""
import logging

import pytest

from handler_fixtures import GRID, U, Recorder, cell_in, cells_in, proposal, rect, state, update
from sharing_msgs.authority import MASTER_CONTROL, single_robot_extent

REACH = 4.0                         # the fleet's sensor reach: a robot's obstacle is at most 9 m across
EXTENT = single_robot_extent(REACH)


def robot(**kwargs):
    return Recorder(duration=1200, max_sensor_reach=REACH, **kwargs)


# ----------------------------------------------------------------------- cells inside the rectangle (item 1)

def test_one_cell_rectangle_holding_forty_thousand_cells_is_refused_and_one_holding_its_cell_is_taken(caplog):
    """The issue's ~600-byte message: a one-cell rectangle and 40,000 cells made 62 % of the facility lethal."""
    r = robot()
    one = rect(0, 0, 0.05, 0.05)
    bomb = update(U("bomb"), marked=tuple(range(40000)), version=1, source="robot_9", rectangle=one, stamp=100.0)
    assert not r.handler.on_external(bomb)          # (beyond the cell cap of a 9 m obstacle, too)
    within_cap = bomb.replace(uuid=U("bomb2"), marked=tuple(range(20000)))
    with caplog.at_level(logging.WARNING, logger="sharing_handler_py"):
        assert not r.handler.on_external(within_cap)
    assert r.handler.counters["dropped_more_cells_than_rectangle"] == 1 and len(r.handler) == 0
    assert "holds at most 1" in caplog.text and "robot_9" in caplog.text
    two = bomb.replace(uuid=U("bomb3"), marked=cells_in(rect(0, 0, 0.1, 0.05)))
    assert not r.handler.on_external(two)           # two cells, one of them beside the one-cell rectangle
    assert r.handler.on_external(update(U("one"), marked=cells_in(one), version=1, source="robot_9", rectangle=one))


def test_a_cell_just_outside_the_rectangle_is_refused_one_on_its_edge_is_taken():
    r = robot()
    area = rect(0, 0, 1, 1)                             # cells with centres 0.025 .. 0.975
    edge = cell_in(area, -1)                            # the last cell inside: centre (0.975, 0.975)
    outside = edge + 1                                  # its neighbour: centre 1.025, half a cell beyond
    assert not r.handler.on_external(update(U("out"), marked=(edge, outside), version=1, rectangle=area))
    assert r.handler.counters["dropped_cells_outside_rectangle"] == 1
    assert not r.handler.on_external(update(U("out2"), cleared=(outside,), marked=(edge,), version=1, rectangle=area))
    assert r.handler.counters["dropped_cells_outside_rectangle"] == 2
    assert r.handler.on_external(update(U("in"), marked=(edge,), version=1, rectangle=area))
    # the layer's own topic and a manual add are held to the same rule
    assert r.handler.on_proposal(proposal(cells=(outside,), rectangle=area)) is None
    assert r.handler.counters["dropped_cells_outside_rectangle"] == 3


# ------------------------------------------------------------------------------------- extent (item 1)

@pytest.mark.parametrize("width,taken", [(EXTENT, True), (EXTENT + 0.05, False)])
def test_a_robots_obstacle_is_at_most_what_one_robot_can_see(width, taken):
    """max_obstacle_extent 10 m admitted a whole 16 x 10 m hall; with a 4 m reach one robot fills at most 9 m."""
    r = robot()
    area = rect(-5, 0, -5 + width, 1)
    assert r.handler.on_external(update(U("wide"), marked=cells_in(area, 1), version=1, rectangle=area,
                                        source="robot_9")) is taken
    assert r.handler.counters["dropped_oversized_rectangle"] == (0 if taken else 1)


@pytest.mark.parametrize("width,taken", [(10.0, True), (10.05, False)])
def test_master_controls_areas_keep_max_obstacle_extent(width, taken):
    r = robot()
    area = rect(-8, 0, -8 + width, 1)
    assert r.handler.on_external(update(U("zone"), marked=cells_in(area, 1), version=1, rectangle=area,
                                        source=MASTER_CONTROL)) is taken


# ----------------------------------------------------------------------------------- provenance (item 2)

def test_an_attackers_obstacle_absorbs_nothing_and_keeps_the_attackers_name():
    """The issue: a 10 x 10 m obstacle absorbed the honest ones inside it and was listed as robot_0's."""
    r = robot()
    good = [(U("g0"), "robot_0", rect(-3, 0, -2.5, 0.5)), (U("g1"), "robot_1", rect(-1, 0, -0.5, 0.5))]
    for uuid, source, area in good:
        r.handler.on_external(update(uuid, marked=cells_in(area, 3), version=1, source=source, rectangle=area))
    before = state(r.handler)
    evil = rect(-4, -1, 4, 1)                                                  # covers both, 8 m: within the cap
    assert r.handler.on_external(update(U("0evil"), marked=cells_in(evil, 50), version=1, source="robot_9",
                                        rectangle=evil, deadline=1200))
    assert [h for h in state(r.handler) if h[0] != U("0evil")] == before       # nothing absorbed or changed
    assert r.handler.get(U("0evil")).source == "robot_9"
    assert r.handler.counters["merged_obstacles"] == 0
    # an honest proposal beside it is an obstacle of its own, not an update renewing the attacker's
    r.clock.now += 100
    mine = r.handler.on_proposal(proposal(cells=cells_in(rect(1, 0, 1.3, 0.3), 2), rectangle=rect(1, 0, 1.3, 0.3)))
    assert mine.uuid != U("0evil") and mine.version == 1
    assert r.handler.get(U("0evil")).remaining == pytest.approx(1100.0)


def test_master_controls_area_never_merges_with_a_robots_obstacle():
    r = robot()
    zone, block = rect(0, 0, 2, 2), rect(2.2, 0, 2.5, 0.5)
    r.handler.on_external(update(U("zone"), marked=cells_in(zone, 4), version=1, source=MASTER_CONTROL, rectangle=zone))
    r.handler.on_external(update(U("block"), marked=cells_in(block, 2), version=1, source="robot_1", rectangle=block))
    r.handler.on_proposal(proposal(cells=cells_in(rect(2.1, 1, 2.3, 1.2), 1), rectangle=rect(2.1, 1, 2.3, 1.2)))
    assert [(h.source, h.rectangle) for h in r.handler.obstacles() if h.uuid in (U("zone"), U("block"))] == \
        [("robot_1", block), (MASTER_CONTROL, zone)]
    assert len(r.handler) == 3 and r.handler.counters["merged_obstacles"] == 0


def test_obstacles_of_one_robot_still_merge_but_never_beyond_what_one_robot_can_see():
    r = robot()
    parts = [rect(0, 0, 4, 1), rect(4.4, 0, 8.9, 1)]           # union 8.9 m: one obstacle
    for k, area in enumerate(parts):
        r.handler.on_external(update(U("p%d" % k), marked=cells_in(area, 2), version=1, source="robot_1",
                                     rectangle=area))
    assert len(r.handler) == 1 and r.handler.counters["merged_obstacles"] == 1
    far = rect(9.3, 0, 9.5, 1)                                 # 0.4 m beyond: the union would be 9.5 m
    r.handler.on_external(update(U("p9"), marked=cells_in(far, 1), version=1, source="robot_1", rectangle=far))
    assert len(r.handler) == 2 and r.handler.counters["merges_refused"] >= 1
    assert max(h.rectangle.max_x - h.rectangle.min_x for h in r.handler.obstacles()) <= EXTENT


def test_until_its_first_share_arrives_an_obstacle_merges_with_nothing_then_as_any_other():
    r = robot()
    a, b = rect(0, 0, 1, 1), rect(1.2, 0, 2, 1)
    r.handler.on_external(update(U("a"), marked=cells_in(a, 1), version=2, source="robot_2", rectangle=a))
    r.handler.on_external(update(U("b"), marked=cells_in(b, 1), version=1, source="robot_1", rectangle=b))
    assert len(r.handler) == 2, "who first shared a is not known yet"
    r.handler.on_external(update(U("a"), marked=cells_in(a, 2)[1:], version=1, source="robot_1", rectangle=a))
    assert len(r.handler) == 1 and r.handler.resolve(U("b")) == U("a")


# ------------------------------------------------------------------------------- removal, renewal (items 3, 4)

def test_a_clear_of_one_cell_with_deadline_one_leaves_the_rest_as_long_lived_as_before():
    r = robot()
    area = rect(0, 0, 1, 1)
    cells = cells_in(area, 4)
    r.handler.on_external(update(U("real"), marked=cells, version=1, source="robot_0", rectangle=area, deadline=1200))
    r.clock.now += 100
    assert r.handler.on_external(update(U("real"), cleared=cells[:1], version=2, source="robot_9", rectangle=area,
                                        deadline=1))
    held = r.handler.get(U("real"))
    assert held.cells == cells[1:] and held.remaining == pytest.approx(1100.0)
    r.clock.now += 10
    assert r.handler.expire() == [] and U("real") in r.handler


def test_a_live_mark_stamped_after_the_tombstone_brings_an_expired_obstacle_back_and_nothing_else_does():
    r = Recorder(duration=60)
    area = rect(0, 0, 1, 1)
    cells = cells_in(area, 2)
    r.handler.on_external(update(U("a"), marked=cells, version=1, rectangle=area, stamp=100.0))
    r.clock.now = 160.0
    assert r.handler.expire() == [U("a")]
    late = update(U("a"), marked=cells, version=2, rectangle=area, stamp=160.0)          # made as it expired
    assert not r.handler.on_external(late)
    assert not r.handler.on_external(late.replace(stamp=170.0, marked=(), cleared=cells[:1]))  # a clear: no
    assert not r.handler.on_state(late.replace(stamp=170.0))                                 # a copy: no
    assert r.handler.counters["dropped_expired"] == 3
    seen = late.replace(version=3, stamp=160.001)
    assert r.handler.on_external(seen)
    assert r.handler.get(U("a")).cells == cells and not r.handler.is_tombstoned(U("a"))
    assert r.handler.counters["revived"] == 1
    assert r.handler.get(U("a")).remaining == pytest.approx(30.0)   # its own deadline (30 s)


def test_renewals_count_only_live_observations():
    """Re-marking one cell every 10 s kept another robot's obstacle at ~1,200 s forever (item 4); a live
    re-mark still renews (the bridge passes only plausible ones), a copy restoring state never does."""
    r = robot()
    area = rect(0, 0, 1, 1)
    cells = cells_in(area, 3)
    r.handler.on_external(update(U("a"), marked=cells, version=1, source="robot_0", rectangle=area, deadline=600))
    for k in range(5):
        r.clock.now += 10
        r.handler.on_state(update(U("a"), marked=cells[:1], version=2 + k, source="robot_9", rectangle=area,
                                  deadline=1200))
    assert r.handler.get(U("a")).remaining == pytest.approx(550.0)
    r.handler.on_external(update(U("a"), marked=cells[:1], version=10, source="robot_1", rectangle=area,
                                 deadline=1200))
    assert r.handler.get(U("a")).remaining == pytest.approx(1200.0)


def test_the_grid_of_the_fixtures_is_the_one_the_cells_are_drawn_on():
    # (guards the helpers above: a cell index means a place only on its grid)
    assert cell_in(rect(0, 0, 1, 1), 0) == GRID.cells_in(rect(0, 0, 1, 1))[0]


def test_a_copy_restoring_state_never_changes_who_first_shared_an_obstacle():
    """A Discover answer goes out under the answering robot's name (coaty_bridge README, authenticated sources): a
    version-1 copy of robot_1's obstacle from robot_0 made robot_0 its creator on robot_1, and robot_1's next
    proposal beside it became an obstacle of its own there while the others merged it (found by
    tests/test/test_fleet_crashes.py after a bridge restart)."""
    r = Recorder("robot_1", duration=1200, max_sensor_reach=REACH)
    mine = r.handler.on_proposal(proposal(cells=cells_in(rect(0, 0, 0.3, 0.1), 2), rectangle=rect(0, 0, 0.3, 0.1),
                                          source="robot_1"))
    copy = mine.replace(source="robot_0", stamp=100.0)
    assert r.handler.on_state(copy)
    assert r.handler.get(mine.uuid).source == "robot_1"
    beside = r.handler.on_proposal(proposal(cells=cells_in(rect(0.5, 0, 0.8, 0.1), 2), rectangle=rect(0.5, 0, 0.8, 0.1),
                                            source="robot_1"))
    assert beside.uuid == mine.uuid and beside.version == 2, "robot_1's proposal beside its own obstacle updates it"
    # an obstacle known only from copies has no known creator: it merges with nothing
    other = Recorder("robot_2", duration=1200, max_sensor_reach=REACH)
    assert other.handler.on_state(copy)
    assert not other.handler._entries[mine.uuid].creator_known


def test_after_a_restart_the_robots_own_updates_handed_back_say_it_first_shared_them():
    """A restarted handler gets its obstacles back as copies under its peers' names (creator unknown) and its own
    updates from its bridge (under its own name): those make it the creator again, so its next proposal beside one
    updates it as on every other robot."""
    r = Recorder("robot_2", duration=1200, max_sensor_reach=REACH)
    area = rect(0, 0, 0.3, 0.1)
    first_share = update(U("mine"), marked=cells_in(area, 2), version=1, source="robot_2", rectangle=area, stamp=100.0)
    assert r.handler.on_state(first_share.replace(source="robot_0"))        # a peer's copy comes first
    assert not r.handler._entries[U("mine")].creator_known
    assert r.handler.on_state(first_share)                                  # then its own, from its bridge
    assert r.handler.get(U("mine")).source == "robot_2" and r.handler._entries[U("mine")].creator_known
    beside = r.handler.on_proposal(proposal(cells=cells_in(rect(0.5, 0, 0.8, 0.1), 2), rectangle=rect(0.5, 0, 0.8, 0.1),
                                            source="robot_2"))
    assert beside.uuid == U("mine")


def test_a_new_share_never_merges_into_an_obstacle_whose_lease_ran_out_before_the_tick():
    """A robot whose obstacle expired shares what it sees again as a new obstacle; on a peer the old one may not
    have been swept yet (the expiry tick comes later). Merged into it, the new marks (version 1 of the new uuid)
    lost to the old clears (version 50 of the old one) per cell: the block showed on the sharing robot, hidden on
    this one until the lease ran out (found by the node test of item 3)."""
    r = robot()
    area = rect(0, 0, 0.2, 0.2)
    cells = cells_in(area)
    old, new = U("a-old"), U("b-new")
    assert old < new                                 # the old one would survive the merge
    r.handler.on_external(update(old, marked=cells, version=1, rectangle=area, deadline=10, stamp=100.0))
    r.handler.on_external(update(old, cleared=cells, version=50, source="robot_3", rectangle=area, deadline=10,
                                 stamp=100.0))
    assert r.handler.get(old).cells == ()            # every cell seen free: hidden, held until its lease ends
    r.clock.now += 10.2                              # its lease ran out; the tick has not run
    assert r.handler.on_external(update(new, marked=cells, version=1, rectangle=area, deadline=60, stamp=110.0))
    assert r.handler.get(old) is None and r.handler.is_tombstoned(old)
    assert r.handler.get(new).cells == cells and r.handler.get(new).source == "robot_1"
    assert r.handler.counters["merged_obstacles"] == 0
