"""The rules of authority of issue 43 (pure): plausible evidence (a peer's cells within its advertised reach of
a pose it advertised near the stamp, each slack at its limit: just inside, just outside) and the cells of a
message inside its rectangle. The same rules in the bridge and handler nodes: coaty_bridge/test/
test_attacks_43_nodes.py."""
import math

import pytest

from sharing_msgs.authority import (AuthorityError, EvidenceRule, PoseHistory, Sighting, check_cells_inside,
                                    rectangle_capacity, single_robot_extent)
from sharing_msgs.authority.policy import PeerPolicy

RES, OX, OY, SX = 0.05, -10.0, -10.0, 400          # a 20 m x 20 m grid
RULE = EvidenceRule(max_sensor_reach=4.0, window=2.0, max_speed=1.0, localisation_tolerance=0.25)
SQUARE = ((-0.3, -0.3), (0.3, -0.3), (0.3, 0.3), (-0.3, 0.3))   # a 0.6 m robot at the origin
RADIUS = math.hypot(0.3, 0.3)


def cell_at(x, y):
    """The cell whose centre is nearest (x, y)."""
    return int(round((y - OY) / RES - 0.5)) * SX + int(round((x - OX) / RES - 0.5))


def centre(cell):
    return OX + (cell % SX + 0.5) * RES, OY + (cell // SX + 0.5) * RES


def allowance(dt=0.0, reach=4.0):
    return min(reach, RULE.max_sensor_reach) + RADIUS + RES / math.sqrt(2) + RULE.localisation_tolerance + \
        RULE.max_speed * dt


def history(stamp=100.0, reach=4.0, valid_for=0.0, points=SQUARE):
    poses = PoseHistory(RULE)
    poses.note("robot_3", Sighting.from_footprint(points, stamp, reach, "map", valid_for))
    return poses


def judge(poses, cells, stamp=100.0, cleared=()):
    return poses.judge("robot_3", stamp, "map", tuple(cells), tuple(cleared), RES, OX, OY, SX)


def cells_along_x(distance):
    """The cell on the +x axis whose centre lies just within (or beyond) ``distance`` of the origin."""
    return cell_at(distance, 0.0)


def just_inside_and_outside(limit):
    """Two cells on the x axis: the farthest whose centre is within ``limit`` and the next one."""
    inside = cell_at(0.0, 0.0)
    while math.hypot(*centre(inside + 1)) <= limit:
        inside += 1
    return inside, inside + 1


# ------------------------------------------------------------------------------------------ the reach

def test_a_cell_just_within_the_reach_and_slack_is_plausible_and_the_next_one_is_not():
    inside, outside = just_inside_and_outside(allowance())
    poses = history()
    ok = judge(poses, [inside])
    assert (ok.marked, ok.refused) == ((inside,), 0)
    bad = judge(poses, [inside, outside], cleared=[outside])
    assert (bad.marked, bad.cleared, bad.refused) == ((inside,), (), 2)
    assert "robot_3" in bad.why and "beyond its reach 4 m" in bad.why and "%d at" % outside in bad.why


def test_an_advertised_reach_beyond_the_receivers_cap_counts_as_the_cap():
    inside, outside = just_inside_and_outside(allowance())
    assert judge(history(reach=50.0), [outside]).refused == 1
    assert judge(history(reach=2.0), [inside]).refused == 1, "a smaller reach is taken as advertised"


def test_the_clear_of_a_robot_eight_metres_away_is_refused():
    """Item 3 of the issue: robot_0's obstacle cleared fleet-wide from a robot parked 8 m away."""
    target = [cell_at(8.0 + 0.05 * k, 0.0) for k in range(5)]
    verdict = judge(history(), [], cleared=target)
    assert verdict.cleared == () and verdict.refused == 5


# ------------------------------------------------------------------------------------------ the window

@pytest.mark.parametrize("offset,plausible", [(2.0, True), (2.001, False), (-2.0, True), (-2.001, False)])
def test_an_advert_is_evidence_only_for_stamps_within_the_window(offset, plausible):
    poses = history(stamp=100.0)
    near = cell_at(1.0, 0.0)
    assert (judge(poses, [near], stamp=100.0 + offset).refused == 0) is plausible


def test_the_robot_may_have_moved_since_the_advert_at_most_max_speed():
    """1.5 s after the advert the allowance is 1.5 m larger, and no more."""
    inside, outside = just_inside_and_outside(allowance(dt=1.5))
    poses = history(stamp=100.0)
    assert judge(poses, [inside], stamp=101.5).refused == 0
    assert judge(poses, [outside], stamp=101.5).refused == 1
    assert judge(poses, [inside], stamp=100.0).refused == 1, "at the advert's own stamp it is too far"


def test_a_parked_robots_advert_holds_for_its_validity_without_growing():
    poses = history(stamp=100.0, valid_for=75.0)
    inside, outside = just_inside_and_outside(allowance(dt=RULE.window))
    assert judge(poses, [inside], stamp=170.0).refused == 0
    assert judge(poses, [outside], stamp=170.0).refused == 1, "parked: at most the window's motion"
    assert judge(poses, [cell_at(1.0, 0.0)], stamp=175.001).refused == 1, "its validity ended"


def test_no_pose_advertised_means_nothing_is_plausible_and_says_so():
    poses = PoseHistory(RULE)
    verdict = poses.judge("robot_9", 100.0, "map", (1, 2), (3,), RES, OX, OY, SX)
    assert verdict.refused == 3 and "never advertised" in verdict.why
    poses = history()
    verdict = poses.judge("robot_3", 100.0, "odom", (cell_at(1.0, 0.0),), (), RES, OX, OY, SX)
    assert verdict.refused == 1 and "frame 'odom'" in verdict.why, "a pose in another frame is no evidence"


def test_a_long_thin_footprint_widens_the_allowance_by_its_radius():
    """The sensor sits on the body: a 0.5 x 5 m robot sees 2.5 m further along its length. (Receivers drop
    adverts wider than max_footprint_extent, 5 m, before they count: the 0.5 x 50 m footprint of the issue is
    no evidence at all; coaty_bridge's test_attacks_43_nodes shows it through the nodes.)"""
    long = ((-2.5, -0.25), (2.5, -0.25), (2.5, 0.25), (-2.5, 0.25))
    radius = math.hypot(2.5, 0.25)
    limit = 4.0 + radius + RES / math.sqrt(2) + RULE.localisation_tolerance
    inside, outside = just_inside_and_outside(limit)
    assert judge(history(points=long), [inside]).refused == 0
    assert judge(history(points=long), [outside]).refused == 1


def test_a_rectangle_wholly_within_reach_is_judged_without_looking_at_each_cell():
    poses = history()
    cells = tuple(cell_at(0.5 + 0.05 * k, 0.5) for k in range(20))
    verdict = poses.judge("robot_3", 100.0, "map", cells, (), RES, OX, OY, SX, rectangle=(0.5, 0.5, 1.5, 0.55))
    assert verdict.marked == cells and verdict.refused == 0


def test_the_history_is_bounded_and_keeps_the_newest():
    poses = PoseHistory(RULE, max_per_robot=3, max_robots=2)
    for k in range(5):
        poses.note("robot_1", Sighting.from_footprint(SQUARE, 100.0 + k, 4.0))
    assert [s.stamp for s in poses.covering("robot_1", 103.0)] == [102.0, 103.0, 104.0]
    poses.note("robot_2", Sighting.from_footprint(SQUARE, 100.0, 4.0))
    poses.note("robot_3", Sighting.from_footprint(SQUARE, 100.0, 4.0))
    assert "robot_1" not in poses and "robot_3" in poses


@pytest.mark.parametrize("field,value", [("max_sensor_reach", -1.0), ("window", math.nan), ("max_speed", 101.0)])
def test_bad_slack_is_refused_naming_it(field, value):
    with pytest.raises(ValueError, match=field):
        EvidenceRule(**{field: value})


# ------------------------------------------------------------------------- cells inside the rectangle

class Rect:
    def __init__(self, *values):
        self.min_x, self.min_y, self.max_x, self.max_y = values

    def __str__(self):
        return str((self.min_x, self.min_y, self.max_x, self.max_y))


def test_every_cell_inside_its_rectangle_and_no_more_than_it_holds():
    area = Rect(0.0, 0.0, 1.0, 0.5)                       # 20 x 10 cells
    assert rectangle_capacity(area, RES, OX, OY) == 200
    corners = [cell_at(0.025, 0.025), cell_at(0.975, 0.475)]
    check_cells_inside(area, corners, (), RES, OX, OY, SX)
    with pytest.raises(AuthorityError, match="cells_outside_rectangle"):
        check_cells_inside(area, corners, [cell_at(1.025, 0.475)], RES, OX, OY, SX)   # half a cell beyond
    with pytest.raises(AuthorityError, match="more_cells_than_rectangle.*holds at most 1"):
        check_cells_inside(Rect(0.0, 0.0, 0.05, 0.05), range(40000), (), RES, OX, OY, SX)


def test_a_rectangle_a_float32_hair_short_still_holds_its_edge_cells():
    import struct
    short = struct.unpack("f", struct.pack("f", 0.999999))[0]
    check_cells_inside(Rect(0.0, 0.0, short, 0.05), [cell_at(0.975, 0.025)], (), RES, OX, OY, SX)


@pytest.mark.parametrize("reach,extent", [(4.0, 9.0), (2.5, 6.0)])
def test_the_extent_one_robot_can_see(reach, extent):
    assert single_robot_extent(reach) == pytest.approx(extent)
    policy = PeerPolicy(max_extent=10.0, max_lifetime=60, max_sensor_reach=reach)
    assert policy.extent_cap("robot_1") == pytest.approx(extent)
    assert policy.extent_cap("master_control") == 10.0
    assert PeerPolicy(max_extent=10.0, max_lifetime=60).extent_cap("robot_1") == 10.0
