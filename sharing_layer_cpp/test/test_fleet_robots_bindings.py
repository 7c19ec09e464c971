"""pytest for the fleet-robot exclusion through the pybind11 module: NumPy in and out, bad input as
ValueError with nothing changed, and a stuck trigger that leaves a known robot out."""
import math

import numpy as np
import pytest

from sharing_layer_cpp import core


def grid():
    return core.GridGeometry(0.05, 0.0, 0.0, 200, 200)


def square(x, y, half=0.325):
    return np.array([[x - half, y - half], [x + half, y - half], [x + half, y + half], [x - half, y + half]])


def ring_scan(origin, boxes, beams=720, max_range=10.0):
    """Points where beams from origin first hit one of the axis-aligned boxes (x0, y0, x1, y1)."""
    ox, oy = origin
    points = []
    for k in range(beams):
        a = 2.0 * math.pi * k / beams
        dx, dy = math.cos(a), math.sin(a)
        best = None
        for x0, y0, x1, y1 in boxes:
            t0, t1 = 0.0, max_range
            for o, d, lo, hi in ((ox, dx, x0, x1), (oy, dy, y0, y1)):
                if abs(d) < 1e-12:
                    if not lo <= o <= hi:
                        t0, t1 = 1.0, 0.0
                    continue
                ta, tb = sorted(((lo - o) / d, (hi - o) / d))
                t0, t1 = max(t0, ta), min(t1, tb)
            if t0 <= t1 and (best is None or t0 < best):
                best = t0
        if best is not None:
            points.append((ox + best * dx, oy + best * dy, 0.3))
    return np.array(points)


def test_update_replace_expire_round_trip():
    c = core.SharingCore(grid(), core.LayerParams(robot_name="robot_0"))
    robots = c.fleet_robots
    assert (robots.margin, robots.timeout, robots.trail) == (0.2, 3.0, 1.0)
    robots.update("robot_1", square(5.0, 5.0), 10.0)
    assert robots.names() == ["robot_1"] and len(robots) == 1
    assert robots.stamp("robot_1") == 10.0
    np.testing.assert_allclose(robots.footprint("robot_1"), square(5.0, 5.0))
    cells = robots.excluded_cells()
    assert cells.dtype == np.uint32
    np.testing.assert_array_equal(cells, core.FleetRobots.rasterize(grid(), square(5.0, 5.0), 0.2))
    assert robots.robots_at(int(cells[len(cells) // 2])) == ["robot_1"]
    robots.replace_all([("robot_2", square(2.0, 2.0), 11.0), ("robot_3", [(7.0, 7.0)], 11.0)])
    assert robots.names() == ["robot_2", "robot_3"]
    assert robots.footprint("robot_1") is None and robots.stamp("robot_1") is None
    assert robots.expire(14.0) == []
    assert robots.expire(14.5) == ["robot_2", "robot_3"]
    assert len(robots.excluded_cells()) == 0
    robots.set_params(margin=0.0, timeout=0.0)
    robots.update("robot_4", square(3.0, 3.0), 1.0)
    assert robots.expire(1e9) == []
    assert robots.forget("robot_4") and not robots.forget("robot_4")


@pytest.mark.parametrize("footprint, stamp, name, why", [
    (np.zeros((0, 2)), 1.0, "robot_1", "vertices"),
    ([[0.0, float("nan")], [1.0, 0.0], [0.0, 1.0]], 1.0, "robot_1", "finite"),
    (square(1.0, 1.0), float("inf"), "robot_1", "stamp"),
    (square(1.0, 1.0), 1.0, "", "name"),
    (square(5.0, 5.0, 40.0), 1.0, "robot_1", "not a robot"),
    (np.zeros((3, 3)), 1.0, "robot_1", "(N, 2)"),
    (np.zeros(4), 1.0, "robot_1", "(N, 2)"),
    ("abc", 1.0, "robot_1", "array"),
])
def test_bad_footprints_raise_and_change_nothing(footprint, stamp, name, why):
    c = core.SharingCore(grid(), core.LayerParams())
    c.fleet_robots.update("robot_9", square(8.0, 8.0), 1.0)
    before = c.fleet_robots.excluded_cells().copy()
    with pytest.raises(ValueError, match=why if why != "(N, 2)" else r"\(N, 2\)"):
        c.fleet_robots.update(name, footprint, stamp)
    with pytest.raises(ValueError):
        c.fleet_robots.replace_all([("robot_8", square(2.0, 2.0), 1.0), (name, footprint, stamp)])
    assert c.fleet_robots.names() == ["robot_9"]
    np.testing.assert_array_equal(before, c.fleet_robots.excluded_cells())


@pytest.mark.parametrize("margin, timeout, trail", [(-0.1, 3.0, 1.0), (float("nan"), 3.0, 1.0), (0.2, -1.0, 1.0),
                                                    (0.2, float("inf"), 1.0), (0.2, 3.0, -0.01), (0.2, 3.0, 10.01),
                                                    (0.2, 3.0, float("nan"))])
def test_bad_params_raise(margin, timeout, trail):
    c = core.SharingCore(grid(), core.LayerParams())
    with pytest.raises(ValueError, match="robot_"):
        c.fleet_robots.set_params(margin=margin, timeout=timeout, trail=trail)
    assert (c.fleet_robots.margin, c.fleet_robots.timeout, c.fleet_robots.trail) == (0.2, 3.0, 1.0)


def test_a_driving_robots_trail_is_excluded_for_the_trail_time():
    c = core.SharingCore(grid(), core.LayerParams())
    robots = c.fleet_robots
    behind = int(core.FleetRobots.rasterize(grid(), [(1.525, 2.025)], 0.001)[0])  # a cell in the 2.0 footprint's margin
    for stamp, x in ((10.0, 2.0), (10.5, 2.5), (11.49, 3.0)):
        robots.update("robot_1", square(x, 2.0), stamp)
    assert behind in robots.excluded_cells()
    robots.update("robot_1", square(3.0, 2.0), 11.51)
    assert behind not in robots.excluded_cells()
    robots.set_params(trail=0.0)
    robots.update("robot_1", square(2.5, 2.0), 11.6)  # backed up 0.5 m: no trail, only the look-ahead ahead
    cells = set(robots.excluded_cells().tolist())
    assert cells == set(core.FleetRobots.rasterize(grid(), square(2.5, 2.0), 0.2).tolist()) | set(
        core.FleetRobots.rasterize(grid(), square(2.0, 2.0), 0.2).tolist())


@pytest.mark.parametrize("known", [False, True])
def test_stuck_trigger_leaves_a_known_robot_out(known):
    block = (4.0, 6.5, 6.0, 6.8)
    body = (6.68, 4.68, 7.32, 5.32)           # robot_1, centred at (7, 5), 2 m from the stuck robot
    c = core.SharingCore(grid(), core.LayerParams(robot_name="robot_0"))
    if known:
        c.fleet_robots.update("robot_1", square(7.0, 5.0), 1.0)
    c.process_scan((5.0, 5.0, 0.3), ring_scan((5.0, 5.0), [block, body]), 1.0)
    report = c.trigger("stuck_feedback", 1.1, 5.0, 5.0)
    assert report.reason == "proposed", report.message
    cells = np.concatenate([p.cells for p in report.proposals])
    xs = (cells % 200 + 0.5) * 0.05
    on_robot = int(np.count_nonzero(xs > 6.5))
    if known:
        assert on_robot == 0, "robot_1 was shared: %s" % report.message
    else:
        assert on_robot > 0, "the scan did not see robot_1: the test could not fail"
