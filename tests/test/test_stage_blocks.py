"""fleet_tests.stage_blocks without Stage: where a block is parked (wholly inside a wall, out of every
laser's reach) and the velocity that drives it to a pose."""
import math
import os

import pytest
import yaml

from fleet_tests import stage_blocks as sb

WORLDS = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
                      "launch", "worlds")


def wall_between(x0, x1):
    """occupied(x, y): a solid wall for x in [x0, x1], free elsewhere."""
    return lambda x, y: x0 <= x <= x1


def test_a_block_parks_in_the_nearest_wall_that_holds_it_with_its_margin():
    # block 2.0 x 0.3 at x = 5 (4..6); a wall 7..10 holds it from centre 8.1 (7 + 1 + 0.1 margin)
    shift = sb.parking_shift((5.0, 1.0, 0.0), (2.0, 0.3), wall_between(7.0, 10.0))
    assert shift == pytest.approx(3.1, abs=0.051)
    # a wall on the other side that is nearer wins
    shift = sb.parking_shift((5.0, 1.0, 0.0), (2.0, 0.3), lambda x, y: 0.0 <= x <= 3.5 or 7.0 <= x <= 10.0)
    assert shift == pytest.approx(-2.6, abs=0.051)


def test_a_wall_just_too_narrow_for_the_block_and_its_margin_is_refused():
    # a 2.0 m block needs 2.2 m of wall with the 0.1 m margins: 2.15 m is not enough, 2.25 m is
    assert sb.parking_shift((5.0, 1.0, 0.0), (2.0, 0.3), wall_between(7.0, 9.15), limit=8.0) is None
    assert sb.parking_shift((5.0, 1.0, 0.0), (2.0, 0.3), wall_between(7.0, 9.25), limit=8.0) is not None


def test_a_turned_block_parks_along_its_own_long_side():
    yaw = math.pi / 2  # the block's x axis is the world's y axis
    occupied = lambda x, y: 7.0 <= y <= 10.0  # noqa: E731
    shift = sb.parking_shift((5.0, 5.0, yaw), (2.0, 0.3), occupied)
    assert shift == pytest.approx(3.1, abs=0.051)


@pytest.mark.parametrize("layout, blocks", [("facility", ["block_middle", "block_right"]),
                                            ("corridors", ["block_short"]), ("deadend", ["block_far"])])
def test_every_block_of_every_world_can_be_taken_away_into_a_wall(layout, blocks):
    from PIL import Image
    with open(os.path.join(WORLDS, layout + ".yaml")) as f:
        meta = yaml.safe_load(f)
    image = Image.open(os.path.join(WORLDS, meta["image"]))
    px, res = image.load(), float(meta["resolution"])

    def occupied(x, y):
        col, row = int(x / res), image.height - 1 - int(y / res)
        if not (0 <= col < image.width and 0 <= row < image.height):
            return True
        return px[col, row] < 128
    goals = "goals.yaml" if layout == "facility" else layout + "_goals.yaml"
    with open(os.path.join(WORLDS, goals)) as f:
        specs = yaml.safe_load(f)["blocks"]
    for name in blocks:
        pose, size = specs[name]["pose"], specs[name]["size"]
        shift = sb.parking_shift(tuple(pose), tuple(size), occupied)
        assert shift is not None, "%s of %s cannot be parked" % (name, layout)
        parked = (pose[0] + shift, pose[1], pose[2])
        assert all(occupied(x, y) for x, y in sb.block_points(parked, size, sb.WALL_MARGIN))


def test_the_velocity_points_at_the_goal_in_the_blocks_own_frame_and_is_capped():
    vx, vy, wz = sb.velocity_towards((0.0, 0.0, 0.0), (10.0, 0.0, 0.0))
    assert (vx, vy, wz) == pytest.approx((sb.MAX_SPEED, 0.0, 0.0))
    # the same world direction seen from a block turned by 90 degrees is its -y
    vx, vy, wz = sb.velocity_towards((0.0, 0.0, math.pi / 2), (10.0, 0.0, math.pi / 2))
    assert (vx, vy, wz) == pytest.approx((0.0, -sb.MAX_SPEED, 0.0), abs=1e-9)
    # near the goal it slows down in proportion, and turns the short way round
    vx, vy, wz = sb.velocity_towards((0.0, 0.0, 0.1), (0.01, 0.0, -0.1))
    assert math.hypot(vx, vy) == pytest.approx(sb.GAIN * 0.01)
    assert wz == pytest.approx(-sb.GAIN * 0.2)
    assert sb.velocity_towards((0.0, 0.0, 3.0), (0.0, 0.0, -3.0))[2] > 0  # across +-pi: 0.28 rad to go


def test_map_occupancy_reads_an_occupancy_grid_and_treats_outside_as_wall():
    class Info:
        width, height, resolution = 2, 1, 0.5

        class origin:
            class position:
                x, y = 1.0, 0.0

    class Grid:
        info = Info
        data = [0, 100]
    occupied = sb.map_occupancy(Grid)
    assert not occupied(1.2, 0.2) and occupied(1.7, 0.2)
    assert occupied(0.9, 0.2) and occupied(1.2, 0.6)
