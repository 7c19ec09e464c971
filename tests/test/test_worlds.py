"""The worlds fleet.launch can run (fleet_launch/worlds, layout:=facility|deadend) load in our
simulator, their maps agree with the simulated walls, and their goals files describe them.

For each layout: the world loads strictly with 1, 2 and 10 robots at the start slots; the map
served by map_server is the floorplan the simulator rasterises, cell by cell, in the same frame
(map frame = Stage world frame); the blocks of the goals file are the world's blocks and are not
in the map; a robot's laser endpoints lie on mapped walls, or on a block where the map is free.
For the dead-end layout also what makes it the scenario it is: the straight way is the long
corridor, the block turns it into a dead end, and the detour is much longer.
"""
import heapq
import math
import os

import numpy as np
import pytest
import rospkg
import yaml
from scipy import ndimage

from fleet_sim import frames
from fleet_sim.map_io import load_map_yaml
from fleet_sim.raycast import core_raycaster
from fleet_sim.sim import Simulation
from fleet_sim.world import load_world
from fleet_sim.world.raster import GridGeometry, paint_floorplan
from fleet_tests.scenario import load_facility

WORLDS = os.path.join(rospkg.RosPack().get_path("fleet_launch"), "worlds")
LAYOUTS = {"facility": "goals.yaml", "deadend": "deadend_goals.yaml", "corridors": "corridors_goals.yaml"}
INSCRIBED = 0.345     # fleet_nav's inscribed radius of the pr2 footprint (its start-up log line)
CLEARANCE = 0.488 + 0.1   # fleet_nav's circumscribed radius of the padded footprint + its clearance_margin


def world_path(layout, robots):
    return os.path.join(WORLDS, "%s_%d.world" % (layout, robots))


def load(layout, robots):
    problems = []
    world = load_world(world_path(layout, robots), strict=True,
                       log=lambda level, msg: problems.append(msg) if level in ("warn", "error") else None)
    assert not problems and not world.problems, problems + world.problems
    return world


def map_of(layout):
    return load_map_yaml(os.path.join(WORLDS, layout + ".yaml"))


def facility(layout):
    return load_facility(os.path.join(WORLDS, LAYOUTS[layout]))


def occupied_world_grid(m):
    """Map cells (rows = y up) that are occupied, and their centres in the world frame."""
    rows, cols = np.mgrid[0:m.height, 0:m.width]
    x = m.origin[0] + (cols + 0.5) * m.resolution
    y = m.origin[1] + (rows + 0.5) * m.resolution
    return m.data == 100, x, y


@pytest.mark.parametrize("layout", sorted(LAYOUTS))
@pytest.mark.parametrize("robots", [1, 2, 10])
def test_world_loads_with_its_robots_at_the_start_slots(layout, robots):
    world = load(layout, robots)
    assert [r.name for r in world.robots] == ["robot_%d" % i for i in range(robots)]
    goals = facility(layout)["goals"]
    for i in range(min(robots, 2)):
        x, y, yaw = goals["start_%d" % i]
        assert world.robots[i].pose == pytest.approx((x, y, yaw), abs=1e-3)
    for r in world.robots:
        assert len(r.rangers) == 1 and r.rangers[0].samples == 1081 and r.rangers[0].range_max == 30.0
    sim = Simulation(world, raycast=core_raycaster())
    for k, r in enumerate(sim.robots):          # nobody starts in a wall, a block or another robot
        assert not sim._collides(r, r.pose), "robot_%d collides at its start" % k


@pytest.mark.parametrize("layout", sorted(LAYOUTS))
def test_map_agrees_with_the_simulated_walls_cell_by_cell(layout):
    world = load(layout, 1)
    m = map_of(layout)
    assert len(world.floorplans) == 1
    fp = world.floorplans[0]
    t_world_map = frames.world_from_map(fp.pose, fp.size, m.origin)
    assert t_world_map == pytest.approx((0.0, 0.0, 0.0), abs=1e-9)     # map frame = Stage world frame
    geom = GridGeometry.covering(world.bounds(1.0), world.resolution)
    grid = np.zeros((geom.size_y, geom.size_x), dtype=np.uint8)
    paint_floorplan(grid, geom, fp)
    occupied, x, y = occupied_world_grid(m)
    wx, wy = frames.apply(t_world_map, x, y)
    gc = np.floor((wx - geom.origin_x) / geom.resolution).astype(int)
    gr = np.floor((wy - geom.origin_y) / geom.resolution).astype(int)
    simulated = grid[gr, gc] != 0
    assert occupied.any() and not occupied.all()
    assert np.array_equal(simulated, occupied), "%d map cells disagree" % np.count_nonzero(simulated != occupied)


@pytest.mark.parametrize("layout", sorted(LAYOUTS))
def test_goals_file_blocks_are_the_world_blocks_and_not_in_the_map(layout):
    world = load(layout, 2)
    desc = facility(layout)
    assert sorted(b.name for b in world.blocks) == sorted(desc["blocks"])
    m = map_of(layout)
    occupied, x, y = occupied_world_grid(m)
    for b in world.blocks:
        spec = desc["blocks"][b.name]
        assert b.pose == pytest.approx(tuple(spec["pose"]), abs=1e-3)
        assert b.size == pytest.approx(tuple(spec["size"]), abs=1e-3)
        cx0, cy0, cx1, cy1 = desc["corridors"][spec["corridor"]]
        assert cx0 <= b.pose[0] <= cx1 and cy0 <= b.pose[1] <= cy1, "%s outside its corridor" % b.name
        # the middle of the block is free in the map: robots must discover it
        inner = (abs(x - b.pose[0]) < b.size[0] / 2 - 0.15) & (abs(y - b.pose[1]) < b.size[1] / 2)
        assert inner.any() and not occupied[inner].any(), "%s is drawn into the map" % b.name
    for name, g in desc["goals"].items():
        col, row = int(g[0] / m.resolution), int(g[1] / m.resolution)
        assert not occupied[row, col], "goal %s lies in a wall" % name


@pytest.mark.parametrize("layout", sorted(LAYOUTS))
def test_laser_endpoints_lie_on_mapped_walls_or_on_blocks(layout):
    """The alignment check of DESIGN.md §7, at every named goal: at least 99% of the endpoints are
    within a cell of an occupied map cell, and each other one lies on a block."""
    world = load(layout, 1)
    sim = Simulation(world, raycast=core_raycaster())
    m = map_of(layout)
    near_wall = ndimage.binary_dilation(m.data == 100, iterations=1)
    desc = facility(layout)
    for name, (gx, gy, gyaw) in sorted(desc["goals"].items()):
        sim.teleport(0, (gx, gy, gyaw))
        r = sim.robots[0]
        ranger = r.spec.rangers[0]
        scan = r.scans[0]
        sx, sy, sth = frames.compose(r.pose, ranger.pose)
        hit = scan < ranger.range_max - 1e-3
        assert hit.all(), "%s: a closed facility, every beam must hit something" % name
        ang = sth + ranger.beam_angles()
        ex, ey = sx + scan * np.cos(ang), sy + scan * np.sin(ang)
        col = np.clip(((ex - m.origin[0]) / m.resolution).astype(int), 0, m.width - 1)
        row = np.clip(((ey - m.origin[1]) / m.resolution).astype(int), 0, m.height - 1)
        on_wall = near_wall[row, col]
        on_block = np.zeros_like(on_wall)
        for b in world.blocks:
            dx, dy = frames.apply(frames.inverse(b.pose), ex, ey)
            on_block |= (np.abs(dx) <= b.size[0] / 2 + 0.05) & (np.abs(dy) <= b.size[1] / 2 + 0.05)
        assert np.all(on_wall | on_block), "%s: %d endpoints on neither a wall nor a block" % (
            name, np.count_nonzero(~(on_wall | on_block)))
        assert np.count_nonzero(on_wall) >= 0.99 * np.count_nonzero(~on_block), name


def shortest(free, start, goal, res):
    """Length in m of the shortest 8-connected path over free cells (inf if none)."""
    h, w = free.shape
    dist = {start: 0.0}
    todo = [(0.0, start)]
    steps = [(dr, dc, math.hypot(dr, dc)) for dr in (-1, 0, 1) for dc in (-1, 0, 1) if dr or dc]
    while todo:
        d, (r, c) = heapq.heappop(todo)
        if (r, c) == goal:
            return d * res
        if d > dist[(r, c)]:
            continue
        for dr, dc, step in steps:
            rr, cc = r + dr, c + dc
            if 0 <= rr < h and 0 <= cc < w and free[rr, cc]:
                nd = d + step
                if nd < dist.get((rr, cc), float("inf")):
                    dist[(rr, cc)] = nd
                    heapq.heappush(todo, (nd, (rr, cc)))
    return float("inf")


def test_deadend_block_turns_the_straight_way_into_a_long_dead_end():
    """Where the robot's centre can go (cells farther than the inscribed radius from a wall): the
    straight way from the start to the goal area runs up the long corridor; with block_far the
    corridor leads nowhere, and the way round is more than twice as long as the straight one."""
    m = map_of("deadend")
    desc = facility("deadend")
    res = m.resolution
    walls = m.data == 100
    occupied, x, y = occupied_world_grid(m)
    b = desc["blocks"]["block_far"]
    (bx, by, _yaw), (bsx, bsy) = b["pose"], b["size"]
    blocked = walls | ((abs(x - bx) <= bsx / 2) & (abs(y - by) <= bsy / 2))

    def free(grid):
        return ndimage.distance_transform_edt(~grid) * res > INSCRIBED

    def cell(name):
        gx, gy, _ = desc["goals"][name]
        return int(gy / res), int(gx / res)

    open_map, closed_map = free(walls), free(blocked)
    straight = shortest(open_map, cell("start_0"), cell("goal_area"), res)
    around = shortest(closed_map, cell("start_0"), cell("goal_area"), res)
    assert straight < 13.0, straight                      # up the long corridor, ~11.8 m
    assert 2.0 * straight < around < float("inf"), (straight, around)
    # from the end of the long corridor, the goal area behind the block is reachable only back
    # through the whole corridor: the far end is a dead end at least 2 x 5 m longer than the door
    via_door = shortest(open_map, cell("far_end"), cell("goal_area"), res)
    back_out = shortest(closed_map, cell("far_end"), cell("goal_area"), res)
    assert via_door < 5.0 and back_out > via_door + 2 * 5.0, (via_door, back_out)
    cx0, cy0, cx1, cy1 = desc["corridors"]["long"]
    assert cy1 - cy0 >= 7.5                                # the blocked corridor is long


@pytest.mark.parametrize("layout", sorted(LAYOUTS))
def test_every_robot_can_leave_and_park_whatever_the_dispatch_order(layout):
    """The bench sends the robots in an order drawn from its seed: with the 9 other robots waiting
    at their start slots, each robot's centre can reach the top of the open corridor keeping
    fleet_nav's clearance (circumscribed radius + clearance_margin) from every wall, block and
    robot; and with bench_goals[0..k-1] taken (farthest first), the k-th robot sent can get from
    there to bench_goals[k]. Robots as 0.75 m squares (0.65 m body, 0.05 m origin offset either way).
    (With the inscribed radius instead, a second row of start slots for N = 20 passed here and
    failed in fleet_nav: robots could not leave between the rows.)"""
    m = map_of(layout)
    desc = facility(layout)
    res = m.resolution
    occupied, x, y = occupied_world_grid(m)
    blocked = occupied.copy()
    for spec in desc["blocks"].values():
        (bx, by, _yaw), (bsx, bsy) = spec["pose"], spec["size"]
        blocked |= (abs(x - bx) <= bsx / 2) & (abs(y - by) <= bsy / 2)
    world = load(layout, 10)
    starts = [(r.pose[0], r.pose[1]) for r in world.robots]
    goals = [(g[0], g[1]) for g in desc["bench_goals"]]
    assert len(starts) == 10 and len(goals) >= 10

    def body(px, py):
        return (abs(x - px) <= 0.375) & (abs(y - py) <= 0.375)

    def cell(px, py):
        return int(py / res), int(px / res)

    def connected(grid, a, b):
        free = ndimage.distance_transform_edt(~grid) * res > CLEARANCE
        labels, _n = ndimage.label(free, structure=np.ones((3, 3)))
        return labels[a] != 0 and labels[a] == labels[b]

    blocked_corridors = {spec["corridor"] for spec in desc["blocks"].values()}
    open_corridors = [c for name, c in desc["corridors"].items() if name not in blocked_corridors]
    assert open_corridors
    x0, _y0, x1, y1 = open_corridors[0]
    exit_cell = cell((x0 + x1) / 2, y1 + 0.5)
    for k, (sx, sy) in enumerate(starts):
        grid = blocked.copy()
        for j, (ox, oy) in enumerate(starts):
            if j != k:
                grid |= body(ox, oy)
        assert connected(grid, cell(sx, sy), exit_cell), "robot_%d cannot leave its start slot" % k
    for k, (gx, gy) in enumerate(goals[:10]):
        grid = blocked.copy()
        for ox, oy in goals[:k]:
            grid |= body(ox, oy)
        assert connected(grid, exit_cell, cell(gx, gy)), "bench_goals[%d] cannot be reached" % k


# --- the robot's body against move_base's footprint (issue 49) ----------------------------------

def footprint_of_config():
    """move_base's footprint polygon and the largest padding the costmaps add (config/move_base)."""
    config = os.path.join(os.path.dirname(WORLDS), "config", "move_base")
    with open(os.path.join(config, "costmap_common_params.yaml")) as f:
        common = yaml.safe_load(f)
    with open(os.path.join(config, "global_costmap_params.yaml")) as f:
        global_pad = yaml.safe_load(f)["global_costmap"].get("footprint_padding", 0.0)
    return [tuple(p) for p in common["footprint"]], max(common.get("footprint_padding", 0.0), global_pad)


def inside_polygon(x, y, polygon, tolerance=1e-9):
    """Point in (or on the edge of) a convex polygon given counterclockwise or clockwise."""
    signs = []
    for (x0, y0), (x1, y1) in zip(polygon, polygon[1:] + polygon[:1]):
        cross = (x1 - x0) * (y - y0) - (y1 - y0) * (x - x0)
        if abs(cross) > tolerance:
            signs.append(cross > 0)
    return all(signs) or not any(signs)


@pytest.mark.parametrize("layout", sorted(LAYOUTS))
def test_the_simulated_body_lies_within_move_bases_footprint(layout):
    """Stage stops a turn that moves the body into a wall; move_base plans with the footprint. A body that
    reaches beyond the footprint (the tutorials' origin -0.05 put its rear corners 0.05 m outside) lets
    move_base command a turn Stage refuses, for ever (issue 49)."""
    footprint, _padding = footprint_of_config()
    for robot in load(layout, 2).robots:
        (sx, sy), (ox, oy) = robot.size, robot.origin
        corners = [(ox + dx * sx / 2, oy + dy * sy / 2) for dx in (-1, 1) for dy in (-1, 1)]
        outside = [c for c in corners if not inside_polygon(c[0], c[1], footprint)]
        assert not outside, "%s of %s: body corners %s outside the footprint %s" % (robot.name, layout, outside,
                                                                                   footprint)


def test_a_body_reaching_past_the_footprint_is_caught():
    footprint, _ = footprint_of_config()
    assert inside_polygon(-0.325, 0.325, footprint)
    assert not inside_polygon(-0.375, 0.325, footprint)   # the old rear corner, origin -0.05


def turning_radius():
    """m a robot turning in place sweeps about its pose: its padded footprint's farthest corner."""
    footprint, padding = footprint_of_config()
    return max(math.hypot(x, y) for x, y in footprint) + padding


@pytest.mark.parametrize("layout", sorted(LAYOUTS))
def test_every_corridor_leaves_room_for_the_robot_turning_in_place(layout):
    """A robot turning in place sweeps the circle of its padded footprint's farthest corner; every corridor is
    wider than that circle with 0.1 m to spare on each side (the dead end's door, as wide as its block, too)."""
    swept = 2 * turning_radius() + 2 * 0.1
    for name, (x0, _y0, x1, _y1) in facility(layout)["corridors"].items():
        assert x1 - x0 >= swept, "%s corridor %s: %.2f m wide, the robot needs %.2f" % (layout, name, x1 - x0, swept)
    if layout == "deadend":
        door = facility(layout)["blocks"]["block_far"]["size"][0] - 0.2   # the block reaches 0.1 m into each jamb
        assert door >= swept, "the dead end's door: %.2f m wide, the robot needs %.2f" % (door, swept)


def goal_tolerance_of_config():
    """base_local_planner's xy_goal_tolerance (config/move_base; its default 0.1 m where the file is silent)."""
    path = os.path.join(os.path.dirname(WORLDS), "config", "move_base", "base_local_planner_params.yaml")
    with open(path) as f:
        return float(yaml.safe_load(f)["TrajectoryPlannerROS"].get("xy_goal_tolerance", 0.1))


def distance_to_walls_and_blocks(x, y, m, blocks):
    """m from (x, y) to the nearest occupied map cell's edge or block's edge."""
    occupied, cx, cy = occupied_world_grid(m)
    half = m.resolution / 2
    dx = np.maximum(np.abs(cx[occupied] - x) - half, 0.0)
    dy = np.maximum(np.abs(cy[occupied] - y) - half, 0.0)
    nearest = float(np.hypot(dx, dy).min())
    for b in blocks.values():
        bdx = max(abs(b["pose"][0] - x) - b["size"][0] / 2, 0.0)
        bdy = max(abs(b["pose"][1] - y) - b["size"][1] / 2, 0.0)
        nearest = min(nearest, math.hypot(bdx, bdy))
    return nearest


def turning_room():
    """m a robot needs from a goal to the nearest wall or block: it stops anywhere within xy_goal_tolerance and
    then turns in place to the goal's yaw."""
    return turning_radius() + goal_tolerance_of_config()


@pytest.mark.parametrize("layout", sorted(LAYOUTS))
def test_every_goal_leaves_room_for_the_robot_turning_in_place_there(layout):
    """A goal closer to a wall than that leaves base_local_planner no way in: sent 0.35 m from the facility's right
    corridor wall, robot_1 turned in place 0.15 m short for ever, its goal ACTIVE; Test 1's old wait_1, 0.45 m from
    it, was not reached in two tries of 120 s in CI."""
    desc, m = facility(layout), map_of(layout)
    need = turning_room()
    goals = dict(desc["goals"])
    goals.update({"bench_goals[%d]" % k: g for k, g in enumerate(desc.get("bench_goals", []))})
    for name, (x, y, _yaw) in sorted(goals.items()):
        room = distance_to_walls_and_blocks(x, y, m, desc["blocks"])
        assert room >= need, "%s goal %s (%.2f, %.2f): %.3f m to the nearest wall or block, a robot turning there " \
                             "needs %.3f" % (layout, name, x, y, room, need)


def test_a_goal_without_turning_room_is_caught():
    """The check above measures: Test 1's old wait_1 (11.75, 4.2) fails it, its new place passes, and a goal
    just inside and just outside the room at the facility's right corridor wall (x = 12.2) are told apart."""
    desc, m = facility("facility"), map_of("facility")
    need = turning_room()
    wall = 12.2
    assert distance_to_walls_and_blocks(11.75, 4.2, m, desc["blocks"]) < need
    assert distance_to_walls_and_blocks(*desc["goals"]["wait_1"][:2], m, desc["blocks"]) >= need
    assert distance_to_walls_and_blocks(wall - need - 0.01, 4.2, m, desc["blocks"]) >= need
    assert distance_to_walls_and_blocks(wall - need + 0.01, 4.2, m, desc["blocks"]) < need
    # a block counts: 0.5 m below block_right's lower face (y = 4.95) is too close
    assert distance_to_walls_and_blocks(11.3, 4.45, m, desc["blocks"]) < need


def test_the_worlds_raster_is_the_one_ground_truth_allows_for():
    from fleet_tests.ground_truth import SIMULATOR_RASTER
    for layout in LAYOUTS:
        with open(os.path.join(WORLDS, layout + ".inc")) as f:
            lines = [line.split() for line in f if line.startswith("resolution")]
        assert lines == [["resolution", repr(SIMULATOR_RASTER)]], layout
