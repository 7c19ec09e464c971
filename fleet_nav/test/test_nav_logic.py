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
from fleet_nav.navigator import ABORT_TEXT, Event, Navigator, RecoveryTrigger, State  # noqa: E402
from fleet_nav.params import NavParams, inscribed_radius  # noqa: E402

# The reference data: $FLEET_SHARED_DATA, else the repository's data/ (data/README.md).
SHARED_DATA = os.environ.get("FLEET_SHARED_DATA") or os.path.join(os.path.dirname(os.path.dirname(HERE)), "data")
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
    # The local controller fails where base_local_planner's forward simulation reaches.
    assert params.sim_time == 1.7 and params.blocked_lookahead == pytest.approx(1.7 * 0.65)
    assert params.acc_lim_th == 3.2 and params.min_in_place_rotational_vel == 0.4
    # The tutorials set none of move_base's own parameters: move_base's defaults hold.
    assert params.planner_frequency == 0.0 and params.planner_patience == 5.0
    assert params.controller_patience == 15.0 and params.oscillation_timeout == 0.0
    assert params.recovery_behavior_enabled and params.clearing_rotation_allowed
    assert params.conservative_reset_dist == 3.0 and not params.stuck_feedback_on_local_failure
    assert "local_costmap/resolution" in unused and "global_costmap/map_type" in unused
    assert "global_costmap/obstacle_range" not in unused


@pytest.mark.parametrize("key,value,words", [
    ("inflation_radius", -0.5, ["inflation_radius", "-0.5"]),
    ("planner_frequency", 500.0, ["planner_frequency", "500"]),
    ("update_frequency", 0.0, ["update_frequency", "0.0"]),
    ("footprint", "[[0, 0], [1]]", ["footprint"]),
    ("max_planning_retries", -2, ["max_planning_retries", "-2"]),
    ("planner_patience", -1.0, ["planner_patience", "-1.0"]),
    ("stuck_feedback_on_local_failure", "yes", ["stuck_feedback_on_local_failure", "yes"]),
    ("conservative_reset/layer_names", "obstacle_layer", ["conservative_reset/layer_names"]),
    ("cost_scaling_factor", "ten", ["cost_scaling_factor", "ten"]),
])
def test_bad_parameters_name_the_parameter_and_value(key, value, words):
    tree = {"global_costmap": {}}
    if key in ("inflation_radius", "update_frequency", "footprint", "cost_scaling_factor"):
        tree["global_costmap"][key] = value
    elif "/" in key:
        tree[key.split("/")[0]] = {key.split("/")[1]: value}
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
    params = params or NavParams(robot_radius=0.2, inflation_radius=0.4, max_vel_x=0.5, sim_time=1.7,
                                 xy_goal_tolerance=0.2, yaw_goal_tolerance=0.2)
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


def approach_lower_door(navigator):
    pose, now, events = (1.0, 1.3, 0.0), 0.0, []
    while pose[0] < 2.3 and now < 20.0:       # until the block is within obstacle_range (2.5 m)
        pose, now, more = drive(navigator, pose, now, 0.1)
        events += more
    return pose, now, events


def test_a_blocked_door_is_a_silent_replan_through_the_other_door_as_in_move_base():
    cm, navigator = make()
    navigator.set_goal(8.0, 1.3, 0.0, 0.0)
    pose, now, events = approach_lower_door(navigator)
    assert events == [Event.PLANNED] and navigator.state is State.CONTROLLING
    mark_block(cm, 4.75, 0.75, 4.95, 1.85, pose)        # the robot now sees the lower door closed
    # planner_frequency 0 (move_base's default): the plan is kept until the controller fails.
    pose, now, events = drive(navigator, pose, now, 0.1)
    assert events == [] and navigator.path_xy[:, 1].max() < 2.5
    pose, now, events = drive(navigator, pose, now, 120.0)
    assert navigator.local_failures == 1                # once the block is within the local planner's reach
    assert events.count(Event.PLANNED) == 1 and Event.STUCK not in events and Event.RECOVERY not in events
    assert events[-1] is Event.SUCCEEDED and pose[1] < 2.0 and pose[0] > 7.0


def test_the_thesis_mode_reports_the_local_failure_as_stuck():
    params = NavParams(robot_radius=0.2, inflation_radius=0.4, max_vel_x=0.5, sim_time=1.7, xy_goal_tolerance=0.2,
                       yaw_goal_tolerance=0.2, stuck_feedback_on_local_failure=True)
    cm, navigator = make(params)
    navigator.set_goal(8.0, 1.3, 0.0, 0.0)
    pose, now, _ = approach_lower_door(navigator)
    mark_block(cm, 4.75, 0.75, 4.95, 1.85, pose)
    pose, now, events = drive(navigator, pose, now, 120.0)
    assert events.count(Event.STUCK) == 1 and events[-1] is Event.SUCCEEDED


def test_with_a_planner_frequency_the_block_is_planned_around_before_the_controller_reaches_it():
    params = NavParams(robot_radius=0.2, inflation_radius=0.4, max_vel_x=0.5, sim_time=1.7, xy_goal_tolerance=0.2,
                       yaw_goal_tolerance=0.2, planner_frequency=1.0, stuck_feedback_on_local_failure=True)
    cm, navigator = make(params)
    navigator.set_goal(8.0, 1.3, 0.0, 0.0)
    pose, now, _ = approach_lower_door(navigator)
    mark_block(cm, 4.75, 0.75, 4.95, 1.85, pose)
    pose, now, events = drive(navigator, pose, now, 1.1)
    assert Event.PLANNED in events and navigator.path_xy[:, 1].max() > 4.0
    pose, now, events = drive(navigator, pose, now, 120.0)
    assert navigator.local_failures == 0 and Event.STUCK not in events and events[-1] is Event.SUCCEEDED


def test_a_box_on_the_plan_is_replanned_around_without_a_recovery():
    cm, navigator = make()
    navigator.set_goal(4.0, 3.0, 0.0, 0.0)
    pose, now, events = drive(navigator, (1.0, 3.0, 0.0), 0.0, 1.0)
    mark_block(cm, 2.5, 2.9, 2.7, 3.1, pose)            # a small box on the straight line
    pose, now, events = drive(navigator, pose, now, 60.0)
    assert Event.STUCK not in events and Event.RECOVERY not in events and Event.SUCCEEDED in events


def test_no_plan_for_planner_patience_runs_the_recoveries_in_move_base_order_then_aborts():
    occ = room()
    occ[:, 100] = 100                                   # both doors closed
    cm, navigator = make(occ=occ)
    navigator.set_goal(8.0, 1.3, 0.0, 0.0)
    pose, now, recoveries, planning_until = (2.0, 1.3, 0.0), 0.0, [], None
    while navigator.active and now < 200.0:
        step = navigator.tick(now, pose)
        if step.recovery:
            recoveries.append((now, step.recovery))
            planning_until = planning_until or now
        x, y, yaw = pose
        pose = (x, y, yaw + step.angular * 0.1)
        now += 0.1
    # planner_patience (5 s) of failed planning, then CLEARING; the next cycle runs the recovery.
    assert planning_until == pytest.approx(navigator.params.planner_patience + 0.2, abs=0.11)
    assert [r[1] for r in recoveries] == [(0, 4, "conservative_reset"), (1, 4, "rotate_recovery"),
                                          (2, 4, "aggressive_reset"), (3, 4, "rotate_recovery")]
    assert Event.ABORTED in step.events and step.reason == ABORT_TEXT[RecoveryTrigger.PLANNING]
    assert not navigator.active
    # Each recovery restarts the patience: the next one follows planner_patience later.
    gaps = np.diff([r[0] for r in recoveries])
    assert (gaps >= navigator.params.planner_patience - 0.05).all()


def test_max_planning_retries_ends_planning_before_the_patience_does():
    occ = room()
    occ[:, 100] = 100
    params = NavParams(robot_radius=0.2, inflation_radius=0.4, max_planning_retries=2)
    cm, navigator = make(params, occ)
    navigator.set_goal(8.0, 1.3, 0.0, 0.0)
    steps, states = [], []
    for t in range(4):
        steps.append(navigator.tick(t * 0.1, (2.0, 1.3, 0.0)))
        states.append(navigator.state)
    # Retries 1 and 2 are allowed, the 3rd failure clears; the next cycle runs the first recovery.
    assert states == [State.PLANNING, State.PLANNING, State.CLEARING, State.PLANNING]
    assert [s.recovery for s in steps] == [None, None, None, (0, 4, "conservative_reset")]


def test_without_recovery_behaviours_a_planning_failure_aborts_at_once_after_the_patience():
    occ = room()
    occ[:, 100] = 100
    params = NavParams(robot_radius=0.2, inflation_radius=0.4, recovery_behavior_enabled=False)
    cm, navigator = make(params, occ)
    navigator.set_goal(8.0, 1.3, 0.0, 0.0)
    now, events = 0.0, []
    while navigator.active and now < 20.0:
        events += navigator.tick(now, (2.0, 1.3, 0.0)).events
        now += 0.1
    assert events == [Event.ABORTED] and now == pytest.approx(5.2, abs=0.15)


def failing_controller(navigator, why="no command"):
    navigator._compute_velocity = lambda now, pose: (None, why)


def test_a_controller_failure_replans_until_controller_patience_then_clears():
    cm, navigator = make()
    navigator.set_goal(8.0, 1.3, 0.0, 0.0)
    navigator.tick(0.0, (2.0, 1.3, 0.0))
    assert navigator.state is State.CONTROLLING and navigator.last_valid_control == 0.0
    failing_controller(navigator)
    step = navigator.tick(0.1, (2.0, 1.3, 0.0))
    assert navigator.state is State.PLANNING and step.linear == step.angular == 0.0
    now, states = 0.2, []
    while now < navigator.params.controller_patience + 1.0:
        step = navigator.tick(now, (2.0, 1.3, 0.0))
        states.append(navigator.state)
        if step.recovery:
            break
        now += 0.1
    # The replan succeeds every time, the controller keeps failing: after controller_patience
    # (15 s) since the last valid command, move_base clears with the CONTROLLING trigger.
    assert now == pytest.approx(navigator.params.controller_patience + 0.2, abs=0.11)
    assert step.recovery == (0, 4, "conservative_reset")
    assert navigator.recovery_trigger is RecoveryTrigger.CONTROLLING
    assert navigator.state is State.PLANNING           # after the recovery, as move_base


def test_a_valid_command_after_a_controller_recovery_starts_the_list_again():
    cm, navigator = make()
    navigator.set_goal(8.0, 1.3, 0.0, 0.0)
    navigator.tick(0.0, (2.0, 1.3, 0.0))
    real = navigator._compute_velocity
    failing_controller(navigator)
    now = 0.1
    while navigator.recovery_index == 0:
        navigator.tick(now, (2.0, 1.3, 0.0))
        now += 0.1
    assert navigator.recovery_index == 1
    navigator._compute_velocity = real
    navigator.tick(now, (2.0, 1.3, 0.0))               # PLANNING -> CONTROLLING -> a valid command
    assert navigator.state is State.CONTROLLING and navigator.recovery_index == 0


def test_oscillation_timeout_clears_with_the_oscillation_trigger_and_a_move_resets_the_list():
    params = NavParams(robot_radius=0.2, inflation_radius=0.4, oscillation_timeout=10.0, oscillation_distance=0.5)
    cm, navigator = make(params)
    navigator.set_goal(8.0, 1.3, 0.0, 0.0)
    now, k, step = 0.0, 0, None
    while now < 12.0:
        pose = (3.0 + (0.2 if k % 20 < 10 else 0.0), 1.3, 0.0)   # back and forth within 0.5 m
        step = navigator.tick(now, pose)
        if step.recovery:
            break
        now, k = now + 0.1, k + 1
    assert now == pytest.approx(10.1, abs=0.15) and step.recovery == (0, 4, "conservative_reset")
    assert navigator.recovery_trigger is RecoveryTrigger.OSCILLATION
    navigator.tick(now + 0.1, (3.8, 1.3, 0.0))          # a move of more than oscillation_distance
    assert navigator.recovery_index == 0


def test_oscillation_is_not_checked_with_move_bases_default_timeout():
    cm, navigator = make()
    navigator.set_goal(8.0, 1.3, 0.0, 0.0)
    for k in range(600):
        step = navigator.tick(k * 0.1, (3.0 + (0.2 if k % 20 < 10 else 0.0), 1.3, 0.0))
        assert step.recovery is None


def test_conservative_reset_clears_own_marks_beyond_3_m_and_keeps_shared_and_near_ones():
    cm, navigator = make()
    g = cm.geometry
    mark_block(cm, 3.0, 1.2, 3.1, 1.4, (2.0, 1.3))         # 1 m from the robot: kept
    mark_block(cm, 2.0, 3.5, 2.1, 3.6, (2.0, 1.3))         # 2.2 m away, outside the 3 m square
    cells = np.array([int(3.05 / RES) * g.size_x + 20], dtype=np.uint32)
    update = core.ObstacleUpdate("u1", cells, np.zeros(0, np.uint32), 60, [0.95, 3.0, 1.05, 3.1], "robot_1", g, 1, 0.0)
    assert cm.layer.apply_shared(update, 0.0).ok
    cleared = cm.clear_obstacles_outside(2.0, 1.3, 3.0, ("obstacle_layer",))
    cm.update(2.0, 1.3)
    assert cleared > 0
    assert cm.costs[int(1.3 / RES), int(3.05 / RES)] == 254
    assert cm.costs[int(3.55 / RES), int(2.05 / RES)] < 253
    assert cm.costs[int(3.05 / RES), 20] == 254            # the shared obstacle stays
    # A layer name move_base would not clear leaves the layer alone.
    mark_block(cm, 2.0, 3.5, 2.1, 3.6, (2.0, 1.3))
    assert cm.clear_obstacles_outside(2.0, 1.3, 3.0, ("voxel_layer",)) == 0


def test_rotate_recovery_turns_a_full_circle_in_place():
    cm, navigator = make()
    navigator.set_goal(8.0, 1.3, 0.0, 0.0)
    navigator.tick(0.0, (2.0, 3.0, 0.0))
    navigator.state, navigator.recovery_index = State.CLEARING, 1   # rotate_recovery is next
    pose, now, turned, recovery = (2.0, 3.0, 0.0), 0.1, 0.0, None
    while now < 30.0:
        step = navigator.tick(now, pose)
        recovery = recovery or step.recovery
        if navigator.state is not State.CLEARING:
            break
        assert step.linear == 0.0 and step.angular > 0.0
        turned += step.angular * 0.1
        pose = (pose[0], pose[1], pose[2] + step.angular * 0.1)
        now += 0.1
    assert recovery == (1, 4, "rotate_recovery")
    assert 2 * math.pi - navigator.params.yaw_goal_tolerance <= turned <= 2 * math.pi + 0.15


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
    params = NavParams(robot_radius=0.2, inflation_radius=0.4, clearance_margin=margin)
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


def test_a_stalled_turn_is_escaped_the_other_way_without_a_controller_failure():
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
    assert events == [Event.SUCCEEDED] and navigator.local_failures == 0


# --- a robot wedged in a doorway (nav_willow under load, issue 28) -----------------------------------
# Under CPU load the Willow robot came into the door at map (20.1, 27.9) at an angle and stood where the
# roll-out of every command touched a lethal cell: the pursuit's turn in place (2·err, ~0 with the
# robot already facing its target) did not move it, each stall escape was blocked and sent (0, 0),
# which counted as valid control, so move_base's replans and recoveries never came and the robot
# waited until the test's 300 s were over.

def test_facing_its_target_with_the_way_ahead_blocked_the_robot_turns_no_slower_than_min_in_place():
    cm, navigator = make()
    pose = (2.0, 3.0, 0.0)
    navigator.set_goal(4.0, 3.0, 0.0, 0.0)
    assert Event.PLANNED in navigator.tick(0.0, pose).events
    # a strip of lethal cells just ahead of the nose (radius 0.2 m), across the way: every forward
    # command's roll-out touches it, the pose itself does not
    cm.costs[int(2.5 / RES):int(3.5 / RES), int(2.25 / RES):int(2.35 / RES)] = 254
    linear, angular = navigator._follow(pose)
    assert navigator.last_command.startswith("turn in place")
    assert linear == 0.0 and abs(angular) >= navigator.params.min_in_place_rotational_vel


def never_free(pose, v, w, horizon=None):
    """A pocket: every move touches an obstacle on the costmap."""
    return v != 0.0 or w != 0.0


def test_a_blocked_stall_escape_gives_way_to_a_free_one():
    cm, navigator = make()
    navigator.set_goal(1.0, 3.0, math.pi, 0.0)      # behind the robot: the pursuit turns in place
    navigator._collides = lambda pose, v, w, horizon=None: v == 0.0 and w != 0.0   # only turning is blocked
    pose, now = (3.0, 3.0, 0.0), 0.0
    commands = []
    while now < 2 * navigator.params.stall_time + 1.0:
        step = navigator.tick(now, pose)             # the body does not move
        commands.append((round(step.linear, 2), navigator.last_command))
        now += 0.1
    escapes = [c for c in commands if c[1].startswith("escape")]
    assert escapes and escapes[0] == (0.15, "escape: creep forward (0.15 m/s, 0.00 rad/s)"), commands[-20:]


def test_a_wedged_robot_ends_in_move_bases_recoveries_not_in_an_endless_wait():
    cm, navigator = make()
    navigator.set_goal(8.0, 1.3, 0.0, 0.0)
    navigator._collides = never_free
    pose, now, events, step = (2.0, 3.0, 0.3), 0.0, [], None
    while now < 300.0 and Event.ABORTED not in events:
        step = navigator.tick(now, pose)             # the body does not move
        events += step.events
        now += 0.1
    assert Event.ABORTED in events, "still waiting after 300 s: %s" % navigator.last_command
    assert step.reason == ABORT_TEXT[RecoveryTrigger.CONTROLLING]
    assert events.count(Event.RECOVERY) == len(navigator.recovery_behaviours)
    assert navigator.local_failures > 0
    assert now < 120.0   # the stalls (1.5 s each) and controller_patience (15 s) per recovery, not 300 s
