"""Simulation core against the known geometry of test/data/room.world.

room.world: 10 m x 8 m room, inner wall faces at x = ±4.9 and y = ±3.9.
robot_0 ("bot0"): 0.4 m square at (0, 0) facing +x, laser 0.1 m ahead, 181 beams
over 180° (beam 90 looks straight ahead), 30 m. robot_1 ("bot1"): omni, at (-3, 2).
"""
import math
import os

import numpy as np
import pytest

import sim_test_helpers as h
from fleet_sim import frames
from fleet_sim.errors import InvalidRequestError
from fleet_sim.map_io import load_map_image
from fleet_sim.sim import LocalisationError, Simulation
from fleet_sim.world import load_world

ROOM = os.path.join(h.DATA, "room.world")
CELL = 0.02
FRONT, LEFT, RIGHT = 90, 180, 0


room = h.room_sim


def drive(sim, index, vx, vy, wz, steps):
    for _ in range(steps):
        sim.set_cmd_vel(index, vx, vy, wz)
        sim.step()


def test_initial_scan_matches_room_geometry():
    sim = room()
    scan = sim.robots[0].scans[0]
    assert scan.shape == (181,) and scan.dtype == np.float32
    assert scan[FRONT] == pytest.approx(4.8, abs=CELL)
    assert scan[LEFT] == pytest.approx(3.9, abs=CELL)
    assert scan[RIGHT] == pytest.approx(3.9, abs=CELL)
    assert scan.max() < 30.0          # a closed room: every beam hits a wall


def test_cmd_vel_moves_robot_and_scan_follows():
    sim = room()
    drive(sim, 0, 0.5, 0.0, 0.0, 20)                  # 2 s at 0.5 m/s
    r = sim.robots[0]
    assert sim.time == pytest.approx(2.0)
    assert r.pose == pytest.approx((1.0, 0.0, 0.0), abs=1e-9)
    assert r.velocity == (0.5, 0.0, 0.0)
    assert r.scans[0][FRONT] == pytest.approx(3.8, abs=CELL)


def test_watchdog_stops_a_robot_without_fresh_commands():
    sim = room(watchdog_timeout=0.2)
    sim.set_cmd_vel(0, 0.5, 0.0, 0.0)
    for _ in range(10):
        sim.step()
    r = sim.robots[0]
    assert r.pose[0] == pytest.approx(0.1)             # moved for 0.2 s only
    assert r.velocity == (0.0, 0.0, 0.0)


def test_diff_drive_ignores_vy_and_omni_moves_sideways():
    sim = room()
    drive(sim, 0, 0.0, 0.5, 0.0, 10)
    assert sim.robots[0].pose == pytest.approx((0.0, 0.0, 0.0))
    drive(sim, 1, 0.0, 0.5, 0.0, 10)                   # bot1 faces -y: its +y is world +x
    assert sim.robots[1].pose == pytest.approx((-2.5, 2.0, -math.pi / 2), abs=1e-9)


def test_rotation_and_arc():
    sim = room()
    drive(sim, 0, 0.0, 0.0, math.pi / 2, 10)
    assert sim.robots[0].pose[2] == pytest.approx(math.pi / 2)
    assert sim.robots[0].scans[0][FRONT] == pytest.approx(3.8, abs=CELL)   # now facing +y


def test_wall_stops_the_robot():
    sim = room()
    drive(sim, 0, 1.0, 0.0, 0.0, 60)
    r = sim.robots[0]
    assert r.stalled and r.velocity == (0.0, 0.0, 0.0)
    assert 4.9 - 0.2 - 0.1 - 1e-9 <= r.pose[0] <= 4.9 - 0.2 + 1e-9   # stopped within one step of the wall
    assert r.scans[0][FRONT] == pytest.approx(4.8 - r.pose[0], abs=CELL)


def test_robots_see_and_stop_at_each_other():
    sim = room()
    sim.teleport(1, (3.0, 0.0, math.pi))               # face to face, 3 m apart
    assert sim.robots[0].scans[0][FRONT] == pytest.approx(2.7, abs=CELL)
    assert sim.robots[1].scans[0][FRONT] == pytest.approx(2.7, abs=CELL)
    drive(sim, 0, 1.0, 0.0, 0.0, 40)
    r0 = sim.robots[0]
    assert r0.stalled and r0.pose[0] + 0.2 <= 2.8 + 1e-9 and r0.pose[0] > 2.8 - 0.4 - 0.1
    assert sim.robots[1].pose[:2] == pytest.approx((3.0, 0.0))
    assert math.cos(sim.robots[1].pose[2]) == pytest.approx(-1.0)


def test_add_move_remove_block_seen_by_the_laser():
    sim = room()
    sim.add_block("crate", 3.0, 0.0, 0.0, 0.4, 0.4)
    assert sim.robots[0].scans[0][FRONT] == pytest.approx(2.7, abs=CELL)
    sim.move_block("crate", 3.0, 3.0, 0.3)
    assert sim.robots[0].scans[0][FRONT] == pytest.approx(4.8, abs=CELL)
    assert sim.blocks["crate"].size == (0.4, 0.4)
    # the moved block is seen where it now is: the beam towards it is short
    ang = math.atan2(3.0, 3.0 - 0.1)
    beam = int(round(math.degrees(ang))) + 90
    assert sim.robots[0].scans[0][beam] < math.hypot(2.9, 3.0)
    sim.remove_block("crate")
    assert "crate" not in sim.blocks
    assert sim.robots[0].scans[0][FRONT] == pytest.approx(4.8, abs=CELL)
    assert not sim.laser_grid[sim.geom.cell_of(3.0, 3.0)[::-1]]


def test_block_stops_a_robot():
    sim = room()
    sim.add_block("wall", 2.0, 0.0, 0.0, 0.2, 2.0)
    drive(sim, 0, 1.0, 0.0, 0.0, 30)
    assert sim.robots[0].stalled and sim.robots[0].pose[0] + 0.2 <= 1.9 + 1e-9


def test_overlapping_blocks_keep_each_other_when_one_moves():
    sim = room()
    sim.add_block("a", 3.0, 0.0, 0.0, 0.4, 0.4)
    sim.add_block("b", 3.1, 0.0, 0.0, 0.4, 0.4)
    sim.remove_block("b")
    assert sim.robots[0].scans[0][FRONT] == pytest.approx(2.7, abs=CELL)


@pytest.mark.parametrize("call, message", [
    (lambda s: s.move_block("crate", 20.0, 0.0, 0.0), "would leave the world"),
    (lambda s: s.move_block("crate", 4.9, 0.0, 0.0), "would leave the world"),
    (lambda s: s.move_block("nope", 1.0, 1.0, 0.0), "no block named 'nope'"),
    (lambda s: s.remove_block("nope"), "no block named 'nope'"),
    (lambda s: s.add_block("crate", 1.0, 1.0, 0.0, 0.4, 0.4), "exists already"),
    (lambda s: s.add_block("neg", 1.0, 1.0, 0.0, -0.4, 0.4), "size must be positive"),
    (lambda s: s.add_block("zero", 1.0, 1.0, 0.0, 0.0, 0.4), "size must be positive"),
    (lambda s: s.add_block("nan", float("nan"), 1.0, 0.0, 0.4, 0.4), "pose must be finite"),
    (lambda s: s.add_block("", 1.0, 1.0, 0.0, 0.4, 0.4), "name must not be empty"),
    (lambda s: s.add_block("onbot", 0.1, 0.0, 0.0, 0.4, 0.4), "would overlap robot_0"),
    (lambda s: s.move_block("crate", -3.0, 2.0, 0.0), "would overlap robot_1"),
    (lambda s: s.set_cmd_vel(0, float("inf"), 0.0, 0.0), "cmd_vel must be finite"),
    (lambda s: s.set_cmd_vel(7, 0.1, 0.0, 0.0), "no robot 7"),
])
def test_bad_requests_are_refused_and_the_simulation_goes_on(call, message):
    sim = room()
    sim.add_block("crate", 3.0, 0.0, 0.0, 0.4, 0.4)
    before = sim.robots[0].scans[0].copy()
    with pytest.raises(InvalidRequestError, match=message):
        call(sim)
    assert sim.blocks["crate"].pose == (3.0, 0.0, 0.0)
    np.testing.assert_array_equal(sim.robots[0].scans[0], before)
    drive(sim, 0, 0.5, 0.0, 0.0, 2)
    assert sim.robots[0].pose[0] == pytest.approx(0.1)


def test_world_file_block_can_be_moved():
    sim = Simulation(load_world(h.WILLOW, log=lambda *a: None), raycast=h.raycaster())
    assert "block:0" in sim.blocks
    col, row = sim.geom.cell_of(-24.269, 48.001)
    assert sim.laser_grid[row, col] and sim.coll_grid[row, col]
    sim.move_block("block:0", -24.269, 46.0, 0.0)
    assert not sim.laser_grid[row, col] and not sim.coll_grid[row, col]


def test_localisation_offset_and_seeded_noise():
    sim = room(seed=7)
    truth = sim.map_to_odom(0)
    assert truth == pytest.approx((5.0, 4.0, 0.0))         # room: map origin at its lower-left corner
    sim.set_localisation_error(0, LocalisationError(dx=0.1, dy=-0.05, dyaw=0.02))
    assert sim.map_to_odom(0) == pytest.approx((5.1, 3.95, 0.02))
    # the error is robot-centred: a yaw error turns the world about the robot, not about the map origin
    sim.teleport(0, (2.0, 1.0, 0.5))
    sim.set_localisation_error(0, LocalisationError(dyaw=0.3))
    believed = frames.compose(sim.map_to_odom(0), sim.robots[0].pose)
    assert believed == pytest.approx((7.0, 5.0, 0.8))

    def noise_run(seed):
        s = room(seed=seed, localisation={1: LocalisationError(std_xy=0.05, std_yaw=0.01)})
        out = []
        for _ in range(200):
            s.step()
            out.append(s.map_to_odom(1))
            assert s.map_to_odom(0) == pytest.approx(truth)      # robot_0 has no error
        return np.array(out)

    a, b, c = noise_run(3), noise_run(3), noise_run(4)
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c)
    assert np.std(a[:, 0]) == pytest.approx(0.05, rel=0.3)
    assert np.std(a[:, 2]) == pytest.approx(0.01, rel=0.3)
    # ground truth is untouched by the error
    sim2 = room(localisation={0: LocalisationError(dx=0.5)})
    assert sim2.robots[0].pose == (0.0, 0.0, 0.0)


def test_same_seed_same_run():
    def run():
        s = room(seed=11, localisation={0: LocalisationError(std_xy=0.02)})
        poses, scans = [], []
        for k in range(30):
            s.set_cmd_vel(0, 0.3, 0.0, 0.2 if k < 15 else -0.2)
            s.set_cmd_vel(1, 0.2, 0.1, 0.1)
            s.step()
            poses.append([r.pose for r in s.robots] + [s.map_to_odom(0)])
            scans.append(np.concatenate([r.scans[0] for r in s.robots]))
        return np.array(poses), np.array(scans)

    p1, s1 = run()
    p2, s2 = run()
    np.testing.assert_array_equal(p1, p2)
    np.testing.assert_array_equal(s1, s2)


def test_robot_starting_inside_a_wall_stays_put_and_does_not_crash(tmp_path):
    text = open(ROOM).read().replace("pose [ 0 0 0 0 ] name \"bot0\"", "pose [ 4.95 0 0 0 ] name \"bot0\"")
    p = tmp_path / "stuck.world"
    p.write_text(text.replace('include "room_robots.inc"', 'include "%s"' % os.path.join(h.DATA, "room_robots.inc"))
                 .replace('bitmap "room.pgm"', 'bitmap "%s"' % os.path.join(h.DATA, "room.pgm")))
    sim = Simulation(load_world(str(p), log=lambda *a: None), raycast=h.raycaster())
    drive(sim, 0, 0.5, 0.0, 0.0, 5)
    assert sim.robots[0].pose[0] == pytest.approx(4.95) and sim.robots[0].stalled


def _endpoints_in_map(sim, index):
    """Scan endpoints through the tf chain map→odom→base_link→laser (odom = world)."""
    r = sim.robots[index]
    ranger = r.spec.rangers[0]
    t_map_laser = frames.compose(frames.compose(sim.map_to_odom(index), r.pose), ranger.pose)
    rng = r.scans[0].astype(np.float64)
    keep = rng < ranger.range_max
    ang = ranger.beam_angles()[keep]
    lx, ly = rng[keep] * np.cos(ang), rng[keep] * np.sin(ang)
    return frames.apply(t_map_laser, lx, ly)


def _fraction_near_occupied(m, xs, ys):
    occ = m.data == 100
    near = occ.copy()                                  # dilate by one cell (8-neighbourhood)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            near |= np.roll(np.roll(occ, dr, axis=0), dc, axis=1)
    col = np.floor((xs - m.origin[0]) / m.resolution).astype(int)
    row = np.floor((ys - m.origin[1]) / m.resolution).astype(int)
    inside = (col >= 0) & (col < m.width) & (row >= 0) & (row < m.height)
    hits = np.zeros(len(xs), dtype=bool)
    hits[inside] = near[row[inside], col[inside]]
    return hits.mean()


def _static_endpoints_in_map(sim, index):
    """Endpoints that hit walls: those near another robot are dropped (no map has robots)."""
    xs, ys = _endpoints_in_map(sim, index)
    keep = np.ones(len(xs), dtype=bool)
    for other in sim.robots:
        if other.index != index:
            ox, oy = frames.apply(sim.map_from_world, other.pose[0], other.pose[1])
            keep &= np.hypot(xs - ox, ys - oy) > 0.6
    return xs[keep], ys[keep]


def _willow():
    world = load_world(h.WILLOW, log=lambda *a: None)
    sim = Simulation(world, raycast=h.raycaster())
    sim.remove_block("block:0")           # not in any map
    # The map as map_server serves it with occupied_thresh 0.5: its occupied cells are
    # then exactly Stage's solid pixels (darker than mid-grey). With map_server's
    # default 0.65 the grey walls (pixel 89..127) are "unknown" -- see README.
    return sim, load_map_image(h.WILLOW_PGM, 0.1, occupied_thresh=0.5)


def test_willow_scans_line_up_with_the_map_served_at_0_1_m():
    sim, m = _willow()
    # the DESIGN.md §7 fact: map (x, y) = Stage (y, -x)
    assert frames.apply(sim.map_from_world, -21.67, 47.12) == pytest.approx((47.12, 21.67))
    for i in range(2):
        xs, ys = _static_endpoints_in_map(sim, i)
        assert len(xs) > 500
        assert _fraction_near_occupied(m, xs, ys) >= 0.95
    # the check can fail: a few cells of localisation error break the alignment
    sim.set_localisation_error(0, LocalisationError(dx=0.3, dy=-0.3))
    xs, ys = _static_endpoints_in_map(sim, 0)
    assert _fraction_near_occupied(m, xs, ys) < 0.8


def test_willow_alignment_holds_while_driving():
    sim, m = _willow()
    drive(sim, 1, 0.3, 0.0, 0.4, 20)
    drive(sim, 0, 0.0, -0.3, -0.3, 15)
    assert sim.robots[1].pose != sim.world.robots[1].pose
    assert sim.robots[0].pose != sim.world.robots[0].pose
    for i in range(2):
        xs, ys = _static_endpoints_in_map(sim, i)
        assert _fraction_near_occupied(m, xs, ys) >= 0.95
