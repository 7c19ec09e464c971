"""fleet_nav's pure logic: move_base parameter files, costmap layers, planning, stuck detection."""
import math
import os

import numpy as np
import pytest
import yaml

HERE = os.path.dirname(os.path.abspath(__file__))

core = pytest.importorskip("sharing_layer_cpp.core")
nav = pytest.importorskip("fleet_nav.nav_core")

from fleet_nav.costmap import GlobalCostmap, static_costs  # noqa: E402
from fleet_nav.errors import GoalRejected, ParameterError  # noqa: E402
from fleet_nav.navigator import Event, Navigator  # noqa: E402
from fleet_nav.params import NavParams, inscribed_radius  # noqa: E402

# The shared data: $FLEET_SHARED_DATA, else ../shared/data beside the repository.
SHARED_DATA = os.environ.get("FLEET_SHARED_DATA") or os.path.join(
    os.path.dirname(os.path.dirname(os.path.dirname(HERE))), "shared", "data")
CONFIG = os.path.join(SHARED_DATA, "move_base_config")


def tutorial_tree():
    """The private parameter tree move_base_multi_robot.launch builds for move_base."""
    def load(name):
        with open(os.path.join(CONFIG, name)) as f:
            return yaml.safe_load(f)
    common = load("costmap_common_params.yaml")
    tree = {"controller_frequency": 10.0, "global_costmap": dict(common), "local_costmap": dict(common)}
    for name in ("local_costmap_params.yaml", "global_costmap_params.yaml", "base_local_planner_params.yaml"):
        for key, value in load(name).items():
            if isinstance(value, dict) and isinstance(tree.get(key), dict):
                tree[key].update(value)
            else:
                tree[key] = value
    return tree


@pytest.mark.skipif(not os.path.isdir(CONFIG), reason="shared move_base_config not found")
def test_tutorial_files_load_with_their_values():
    params, unused = NavParams.from_dict(tutorial_tree(), "robot_0")
    assert params.obstacle_range == 2.5 and params.raytrace_range == 3.0
    assert params.inflation_radius == 0.55 and params.cost_scaling_factor == 10.0
    assert params.update_frequency == 5.0 and params.controller_frequency == 10.0
    assert params.robot_base_frame == "robot_0/base_link" and params.global_frame == "map"
    # global_costmap_params' footprint_padding 0.02 wins over the common 0.01, as in costmap_2d.
    assert params.footprint[0] == pytest.approx((-0.345, -0.345))
    assert params.inscribed_radius == pytest.approx(0.345)
    assert params.max_vel_x == 0.65 and params.xy_goal_tolerance == 0.1
    # The way past a blockage is searched in the local costmap's 6 m x 6 m rolling window.
    assert params.local_window == 6.0 and "local_costmap/width" not in unused
    assert "local_costmap/resolution" in unused and "global_costmap/map_type" in unused
    assert "global_costmap/obstacle_range" not in unused


@pytest.mark.parametrize("key,value,words", [
    ("inflation_radius", -0.5, ["inflation_radius", "-0.5"]),
    ("planner_frequency", 500.0, ["planner_frequency", "500"]),
    ("update_frequency", 0.0, ["update_frequency", "0.0"]),
    ("footprint", "[[0, 0], [1]]", ["footprint"]),
    ("max_failures", 0, ["max_failures", "0"]),
    ("cost_scaling_factor", "ten", ["cost_scaling_factor", "ten"]),
])
def test_bad_parameters_name_the_parameter_and_value(key, value, words):
    tree = {"global_costmap": {}}
    if key in ("inflation_radius", "update_frequency", "footprint", "cost_scaling_factor"):
        tree["global_costmap"][key] = value
    else:
        tree[key] = value
    with pytest.raises(ParameterError) as err:
        NavParams.from_dict(tree, "robot_0")
    for word in words:
        assert word in str(err.value)


def test_inscribed_radius_of_a_square():
    assert inscribed_radius(((-1, -1), (-1, 1), (1, 1), (1, -1))) == pytest.approx(1.0)


def test_static_layer_interprets_occupancy_like_costmap_2d():
    occ = np.array([0, 50, 99, 100, -1], dtype=np.int8)
    assert static_costs(occ).tolist() == [0, 0, 0, 254, 0]
    assert static_costs(occ, 50, True).tolist() == [0, 254, 254, 254, 255]


# --- a small world: a 10 m x 6 m room split by a wall with two doors ------------------------------
RES = 0.05


def room(block_upper_door=False):
    w, h = int(10 / RES), int(6 / RES)
    occ = np.zeros((h, w), dtype=np.int8)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = 100
    occ[:, 100] = 100                          # wall at x = 5 m
    occ[int(0.8 / RES):int(1.8 / RES), 100] = 0   # lower door y 0.8..1.8
    occ[int(4.2 / RES):int(5.2 / RES), 100] = 0   # upper door y 4.2..5.2
    return occ


def make(params=None, occ=None):
    params = params or NavParams(robot_radius=0.2, inflation_radius=0.4, planner_frequency=0.5,
                                 local_window=5.0, max_failures=3)
    occ = room() if occ is None else occ
    geometry = core.GridGeometry(RES, 0.0, 0.0, occ.shape[1], occ.shape[0])
    layer = core.LayerParams(obstacle_range=2.5, raytrace_range=3.0, robot_name="robot_0")
    cm = GlobalCostmap(geometry, occ.reshape(-1), params, layer)
    return cm, Navigator(params, cm)


def mark_block(cm, x0, y0, x1, y1, robot):
    """A scan whose endpoints cover a block, as the laser would see its face."""
    pts = [(x, y, 0.0) for x in np.arange(x0, x1, RES / 2) for y in np.arange(y0, y1, RES / 2)]
    cm.layer.process_scan((robot[0], robot[1], 0.0), np.array(pts), 1.0)
    cm.update(robot[0], robot[1])


def drive(navigator, pose, now, seconds, dt=0.1):
    """Integrates the commands (unicycle); returns the final pose, the time and all events."""
    events = []
    for _ in range(int(seconds / dt)):
        step = navigator.tick(now, pose)
        events += step.events
        x, y, yaw = pose
        pose = (x + step.linear * math.cos(yaw) * dt, y + step.linear * math.sin(yaw) * dt, yaw + step.angular * dt)
        now += dt
        if Event.SUCCEEDED in step.events or Event.ABORTED in step.events:
            break
    return pose, now, events


def test_inflation_around_the_wall():
    cm, _ = make()
    assert cm.costs[60, 100] == 254                     # wall
    assert cm.costs[60, 97] == 253                      # 0.15 m < inscribed 0.2 m
    assert 0 < cm.costs[60, 94] < 253                   # 0.3 m: decayed
    assert cm.costs[60, 80] == 0                        # 1 m: free


def test_plan_goes_through_the_nearer_door_and_robot_reaches_goal():
    cm, navigator = make()
    navigator.set_goal(8.0, 1.3, 0.0, 0.0)
    pose, _, events = drive(navigator, (2.0, 1.3, 0.0), 0.0, 60.0)
    assert Event.SUCCEEDED in events and Event.STUCK not in events
    assert math.hypot(pose[0] - 8.0, pose[1] - 1.3) <= navigator.params.xy_goal_tolerance


def test_blocked_door_reports_stuck_once_then_takes_the_other_door():
    cm, navigator = make()
    navigator.set_goal(8.0, 1.3, 0.0, 0.0)
    pose, now, events = (1.0, 1.3, 0.0), 0.0, []
    while pose[0] < 2.3 and now < 20.0:       # until the block is within obstacle_range (2.5 m)
        pose, now, more = drive(navigator, pose, now, 0.1)
        events += more
    assert Event.PLANNED in events and Event.STUCK not in events
    # The robot now sees the lower door closed.
    mark_block(cm, 4.75, 0.75, 4.95, 1.85, pose)
    pose, now, events = drive(navigator, pose, now, 120.0)
    assert events.count(Event.STUCK) == 1
    assert Event.SUCCEEDED in events
    assert navigator.failures == 1


def test_block_with_room_to_pass_is_no_failure():
    cm, navigator = make()
    navigator.set_goal(4.0, 3.0, 0.0, 0.0)
    pose, now, events = drive(navigator, (1.0, 3.0, 0.0), 0.0, 1.0)
    mark_block(cm, 2.5, 2.9, 2.7, 3.1, pose)            # a small box on the straight line
    pose, now, events = drive(navigator, pose, now, 60.0)
    assert Event.STUCK not in events and Event.SUCCEEDED in events


def test_both_doors_closed_aborts_after_max_failures():
    occ = room()
    occ[:, 100] = 100
    cm, navigator = make(occ=occ)
    navigator.set_goal(8.0, 1.3, 0.0, 0.0)
    _, _, events = drive(navigator, (2.0, 1.3, 0.0), 0.0, 30.0)
    assert events[-1] is Event.ABORTED and Event.SUCCEEDED not in events
    assert navigator.failures == navigator.params.max_failures and not navigator.active


def test_goals_outside_or_in_obstacles_are_rejected_with_a_reason():
    cm, _ = make()
    with pytest.raises(GoalRejected, match="outside the map"):
        cm.check_goal(12.0, 1.0)
    with pytest.raises(GoalRejected, match="inside an obstacle"):
        cm.check_goal(5.0 + RES / 2, 3.0)
    with pytest.raises(GoalRejected, match="inscribed"):
        cm.check_goal(4.9, 3.0)
    cm.check_goal(3.0, 3.0)


def test_shared_cells_are_lethal_and_survive_the_obstacle_layer_reset():
    cm, navigator = make()
    g = cm.geometry
    cells = np.array([int(y / RES) * g.size_x + 100 for y in np.arange(0.8, 1.8, RES)], dtype=np.uint32)
    update = core.ObstacleUpdate("u1", cells, np.zeros(0, np.uint32), 60, [4.9, 0.8, 5.1, 1.8], "robot_1", g, 1, 0.0)
    assert cm.layer.apply_shared(update, 0.0).ok
    mark_block(cm, 2.0, 2.0, 2.1, 2.1, (1.0, 1.0))
    cm.reset_obstacle_layer()
    cm.update(1.0, 1.0)
    assert cm.costs[int(2.05 / RES), int(2.05 / RES)] < 253      # obstacle layer cleared
    assert cm.costs[int(1.3 / RES), 100] == 254                  # shared door block stays
    assert cm.shared_mask().sum() == len(cells)
    # A robot far away plans through the upper door from the start.
    navigator.set_goal(8.0, 1.3, 0.0, 0.0)
    step = navigator.tick(0.0, (2.0, 1.3, 0.0))
    assert Event.PLANNED in step.events
    assert navigator.path_xy[:, 1].max() > 4.0


def test_snapshot_draws_shared_obstacles_in_their_colour(tmp_path):
    from fleet_nav import snapshot
    cm, navigator = make()
    mask = np.zeros(cm.shape, dtype=bool)
    mask[10:12, 10:12] = True
    navigator.set_goal(8.0, 1.3, 0.0, 0.0)
    navigator.tick(0.0, (2.0, 1.3, 0.0))
    img = snapshot.render(cm.costs, mask, cm.geometry, (2.0, 1.3, 0.0), navigator.params.footprint_polygon,
                          navigator.path_xy, scale=1)
    img.save(str(tmp_path / "view.png"))
    px = np.asarray(img)
    assert tuple(px[cm.shape[0] - 1 - 10, 10]) == snapshot.SHARED_RGB
    assert (px == snapshot.PLAN_RGB).all(axis=-1).sum() > 50


def test_a_blockage_that_fades_after_the_stuck_is_not_reported_again():
    # After a stop about obstacle_range before a block, turning away erases part of its face
    # (cells seen between obstacle_range and raytrace_range are cleared, as in costmap_2d). The
    # navigator remembers the blockage for this goal, so it does not turn back into it.
    cm, navigator = make()
    block = (4.75, 0.75, 4.95, 1.85)
    navigator.set_goal(8.0, 1.3, 0.0, 0.0)
    pose, now, events, faded = (1.0, 1.3, 0.0), 0.0, [], False
    while now < 120.0 and Event.SUCCEEDED not in events and Event.ABORTED not in events:
        # The laser sees the block's face within obstacle_range (2.5 m).
        if math.hypot(pose[0] - block[0], pose[1] - 1.3) < 2.5:
            mark_block(cm, *block, pose)
        if Event.STUCK in events and not faded:
            cm.reset_obstacle_layer()              # the whole face is gone from the obstacle layer
            cm.update(pose[0], pose[1])
            faded = True
        pose, now, more = drive(navigator, pose, now, 0.1)
        events += more
    assert events.count(Event.STUCK) == 1 and Event.SUCCEEDED in events
    # A new goal forgets the blockage.
    cm.reset_obstacle_layer()
    cm.update(2.0, 1.3)
    navigator.set_goal(8.0, 1.3, 0.0, now)
    navigator.tick(now, (2.0, 1.3, 0.0))
    assert navigator.path_xy[:, 1].max() < 2.5


def narrow_door_room(door_width):
    occ = room()
    occ[int(0.8 / RES):int(1.8 / RES), 100] = 100
    lo = int(round((1.3 - door_width / 2) / RES))
    occ[lo:lo + int(round(door_width / RES)), 100] = 0
    return occ


@pytest.mark.parametrize("margin,lower_door", [(0.1, False), (0.0, True)])
def test_plans_keep_a_clearance_margin_where_there_is_room(margin, lower_door):
    # The lower door is 0.6 m: the robot (inscribed 0.2 m) fits, but a scan endpoint one cell in
    # front of the door frame closes it. With the margin the plan takes the wide upper door.
    params = NavParams(robot_radius=0.2, inflation_radius=0.4, planner_frequency=0.5, local_window=5.0,
                       max_failures=3, clearance_margin=margin)
    cm, navigator = make(params, narrow_door_room(0.6))
    navigator.set_goal(8.0, 1.3, 0.0, 0.0)
    assert Event.PLANNED in navigator.tick(0.0, (2.0, 1.3, 0.0)).events
    assert (navigator.path_xy[:, 1].max() < 2.5) == lower_door


def test_the_only_narrow_way_is_still_planned():
    occ = narrow_door_room(0.6)
    occ[int(4.2 / RES):int(5.2 / RES), 100] = 100       # upper door closed
    cm, navigator = make(occ=occ)
    navigator.set_goal(8.0, 1.3, 0.0, 0.0)
    assert Event.PLANNED in navigator.tick(0.0, (2.0, 1.3, 0.0)).events


def test_local_window_comes_from_the_local_costmap_and_must_reach_past_the_lookahead():
    params, _ = NavParams.from_dict({"local_costmap": {"width": 5.0, "height": 4.5}})
    assert params.local_window == 4.5
    with pytest.raises(ParameterError, match=r"local_window \(3.0 m\).*blocked_lookahead \(2.0 m\)"):
        NavParams.from_dict({"local_costmap": {"width": 3.0, "height": 3.0}})


def test_a_stalled_turn_is_escaped_the_other_way_before_it_counts_as_a_failure():
    # The body touches something the footprint check cannot see (a Stage model larger than the
    # configured footprint): turning left does not move the robot. The goal is behind it.
    cm, navigator = make()
    navigator.set_goal(1.0, 3.0, math.pi, 0.0)
    pose, now, events, escaped = (3.0, 3.0, 0.0), 0.0, [], False
    while now < 40.0 and not events:
        step = navigator.tick(now, pose)
        events += [e for e in step.events if e is not Event.PLANNED]
        x, y, yaw = pose
        if step.linear == 0.0 and step.angular > 0:
            step.angular = 0.0                       # the stall: the body cannot turn left in place
        escaped |= navigator.last_command.startswith("escape")
        pose = (x + step.linear * math.cos(yaw) * 0.1, y + step.linear * math.sin(yaw) * 0.1, yaw + step.angular * 0.1)
        now += 0.1
    assert escaped
    assert events == [Event.SUCCEEDED] and navigator.failures == 0
    assert now < navigator.params.stuck_timeout


def test_going_back_and_forth_without_getting_closer_is_a_failure_and_the_replan_avoids_that_way(caplog):
    # Something unseen holds the robot in front of the lower door: it moves, but only back and forth.
    cm, navigator = make()
    navigator.set_goal(8.0, 1.3, 0.0, 0.0)
    now, k, old_plan = 0.0, 0, None
    with caplog.at_level("WARNING", logger="fleet_nav.navigator"):
        while now < navigator.params.stuck_timeout + 5.0 and navigator.failures == 0:
            pose = (3.0 + (0.15 if k % 20 < 10 else 0.0), 1.3, 0.0)
            old_plan = navigator.path_xy.copy()
            navigator.tick(now, pose)
            now, k = now + 0.1, k + 1
    assert navigator.failures == 1
    assert now > navigator.params.stuck_timeout
    assert "no progress for 20.0 s at (3." in caplog.text and "last command" in caplog.text

    def cells_ahead(plan):
        d = np.hypot(plan[:, 0] - pose[0], plan[:, 1] - pose[1])
        return {cm.world_to_cell(x, y) for x, y in plan[(d > 0.4) & (d < 1.4)]}
    # The next plan does not take the cells ahead it could not make progress along.
    step = navigator.tick(now, pose)
    assert Event.PLANNED in step.events
    assert cells_ahead(old_plan) and not cells_ahead(old_plan) & cells_ahead(navigator.path_xy)


def test_a_block_seen_when_a_replan_is_due_is_a_stuck_not_a_silent_reroute():
    # The laser marks the block 2.5 m out, the path check looks blocked_lookahead (2 m) ahead: a
    # periodic replan falling in between must not route around the block without a stuck_feedback.
    cm, navigator = make()
    navigator.set_goal(8.0, 1.3, 0.0, 0.0)
    pose, now = (1.0, 1.3, 0.0), 0.0
    while pose[0] < 2.3 and now < 20.0:
        pose, now, _ = drive(navigator, pose, now, 0.1)
    mark_block(cm, 4.75, 0.75, 4.95, 1.85, pose)        # the door is closed 2.3-2.5 m ahead
    assert navigator._blocked_at(pose, navigator.params.blocked_lookahead) == -1
    navigator.next_plan = now                           # the periodic replan is due on this tick
    step = navigator.tick(now, pose)
    assert step.events == [Event.STUCK]
