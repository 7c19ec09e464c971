"""The fleet bench's metrics (fleet_tests.bench) on synthetic inputs and on the geometry of both
layouts' goals files: crossing a blocked corridor's mouth, the seeded dispatch, obstacles after
merging and which were robots or walls, and the broker's $SYS byte accounting."""
import importlib.machinery
import json
import math
import importlib.util
import os

import pytest
import rospkg

from fleet_tests.bench import (OccupancyIndex, block_rect, broker_bytes, classify_obstacles, crossed_mouth,
                               dispatch_plan, obstacle_groups, pose_at, rect_gap, sys_message_bytes)
from fleet_tests.scenario import load_facility

WORLDS = os.path.join(rospkg.RosPack().get_path("fleet_launch"), "worlds")


def block_and_corridor(goals, name):
    f = load_facility(os.path.join(WORLDS, goals))
    b = f["blocks"][name]
    return b, f["corridors"][b["corridor"]]


# --- crossing the mouth line of a blocked corridor ---------------------------------------------

@pytest.mark.parametrize("track, expected", [
    ([(0, 13.6, 1.0), (1, 13.6, 8.4)], True),      # drove 5 m up the long corridor, turned 2.5 m before the block
    ([(0, 13.6, 1.0), (1, 13.6, 3.2)], False),     # stopped 0.2 m below the mouth line
    ([(0, 13.6, 1.0), (1, 13.6, 3.4)], True),      # reached the mouth line
    ([(0, 15.0, 1.0), (1, 15.0, 3.3), (2, 15.5, 3.5)], False),   # beside the corridor (x > 14.6), not through the mouth
    ([(0, 1.9, 2.0), (1, 1.9, 9.0), (2, 13.3, 13.9)], False),    # the detour, then behind the block
    ([(0, 13.3, 13.9), (1, 13.1, 12.0)], False),   # from the goal hall towards the block: not the mouth line
])
def test_deadend_mouth(track, expected):
    _block, corridor = block_and_corridor("deadend_goals.yaml", "block_far")
    assert crossed_mouth(track, corridor) is expected


@pytest.mark.parametrize("track, expected", [
    ([(0, 12.07, 2.73)], False),                   # Test 1's first stuck, below the right corridor's mouth
    ([(0, 11.3, 2.0), (1, 11.3, 3.0), (2, 11.3, 2.2)], False),   # 0.4 m short of the mouth, backed off
    ([(0, 11.3, 3.0), (1, 11.3, 3.6), (2, 11.3, 3.0)], True),    # in by 0.2 m, backed out
    ([(0, 10.0, 3.0), (1, 12.6, 3.8)], True),      # diagonally: crosses y = 3.4 at x = 11.3
    ([(0, 9.0, 3.0), (1, 10.2, 3.8)], False),      # diagonally: crosses y = 3.4 at x = 9.6, left of the mouth
    ([(0, 11.3, 7.3)], False),                     # purple: behind the block
])
def test_facility_mouth(track, expected):
    _block, corridor = block_and_corridor("goals.yaml", "block_right")
    assert crossed_mouth(track, corridor) is expected


# --- seeded dispatch ----------------------------------------------------------------------------

def test_dispatch_same_seed_same_plan_and_seeds_differ():
    assert dispatch_plan(10, 3, 20.0) == dispatch_plan(10, 3, 20.0)
    plans = {tuple(dispatch_plan(10, s, 20.0)) for s in range(1, 6)}
    assert len(plans) == 5
    orders = {tuple(i for i, _w in dispatch_plan(10, s, 20.0)) for s in range(1, 6)}
    assert len(orders) == 5                         # the order changes with the seed, not only the waits


@pytest.mark.parametrize("seed", [1, 2, 3, 17])
def test_dispatch_is_a_permutation_with_bounded_waits(seed):
    plan = dispatch_plan(20, seed, 20.0)
    assert sorted(i for i, _w in plan) == list(range(20))
    assert plan[0][1] == 0.0
    assert all(10.0 <= w <= 30.0 for _i, w in plan[1:])
    assert dispatch_plan(1, seed, 20.0) == [(0, 0.0)]


def test_dispatch_waits_spread_over_the_range():
    waits = [w for s in range(50) for _i, w in dispatch_plan(5, s, 10.0)[1:]]
    assert min(waits) < 6.0 and max(waits) > 14.0   # uniform 0.5..1.5 x interval, not a constant


# --- obstacles after merging --------------------------------------------------------------------

def test_rect_gap():
    assert rect_gap((0, 0, 1, 1), (0.5, 0.5, 2, 2)) == 0.0
    assert rect_gap((0, 0, 1, 1), (1.3, 0, 2, 1)) == pytest.approx(0.3)
    assert rect_gap((0, 0, 1, 1), (1.3, 1.8, 2, 2)) == pytest.approx(0.8)   # the axis where they lie farthest apart


def test_groups_merge_close_live_obstacles_only():
    msgs = [
        (10.0, "a", (0.0, 0.0, 1.0, 0.3)),
        (10.5, "b", (1.3, 0.0, 2.0, 0.3)),          # 0.3 m from a, both alive: merged
        (11.0, "a", (0.0, 0.0, 1.0, 0.3)),
        (12.0, "c", (5.0, 5.0, 6.0, 5.3)),          # far away: its own obstacle
        (200.0, "d", (0.0, 0.0, 1.0, 0.3)),         # same place, but a expired at 71 s: a new obstacle
        (13.0, "", (0.0, 0.0, 1.0, 1.0)),           # a proposal, no uuid: not an obstacle
    ]
    assert obstacle_groups(msgs, 0.5, 60.0) == [["a", "b"], ["c"], ["d"]]
    assert obstacle_groups(msgs, 0.2, 60.0) == [["a"], ["b"], ["c"], ["d"]]
    assert obstacle_groups(msgs, 0.5, 600.0) == [["a", "b", "d"], ["c"]]


def test_groups_merge_transitively_through_grown_rectangles():
    msgs = [(0.0, "x", (0.0, 0.0, 1.0, 1.0)), (1.0, "y", (3.0, 0.0, 4.0, 1.0)),
            (2.0, "y", (1.2, 0.0, 4.0, 1.0))]       # y grew towards x: within 0.5 m
    assert obstacle_groups(msgs, 0.5, 60.0) == [["x", "y"]]


def test_pose_at_interpolates():
    track = [(0.0, 0.0, 0.0), (1.0, 1.0, 0.0), (2.0, 1.0, 2.0)]
    assert pose_at(track, 0.5) == pytest.approx((0.5, 0.0))
    assert pose_at(track, 1.5) == pytest.approx((1.0, 1.0))
    assert pose_at(track, 2.5) is None and pose_at([], 0.0) is None


# --- which obstacles were robots, which walls --------------------------------------------------

def small_map():
    """10 x 10 cells of 0.1 m at the origin; the bottom row (y 0..0.1) is a wall."""
    data = [100 if iy == 0 else 0 for iy in range(10) for _ix in range(10)]
    return OccupancyIndex(10, 10, 0.1, 0.0, 0.0, data)


def test_occupancy_near():
    grid = small_map()
    assert grid.near(0.55, 0.15, 0.1)          # 0.05 above the wall
    assert grid.near(0.55, 0.2, 0.1)           # 0.1 above it: on the limit
    assert not grid.near(0.55, 0.25, 0.1)      # 0.15 above it
    assert not grid.near(0.55, 0.95, 0.1)


def test_classify_robot_wall_block_and_clean():
    tracks = {"robot_0": [(0.0, 5.0, 5.0), (10.0, 5.0, 5.0)],
              "robot_1": [(0.0, 2.0, 2.0), (5.0, 2.0, 2.0), (10.0, 3.0, 2.0)]}
    groups = [["on_robot"], ["on_wall"], ["on_block"], ["clean"], ["own_pose"], ["robot_moved_away"]]
    walls = small_map()
    blocks = [block_rect({"pose": [0.5, 0.3, 0.0], "size": [0.2, 0.2]}),    # a block against the wall at x 0.4..0.6
              block_rect({"pose": [5.0, 9.0, 0.0], "size": [1.0, 0.3]})]    # and one elsewhere
    cells = [
        (5.0, "robot_0", "on_robot", [(8.0, 8.0), (2.52, 2.0)]),   # 0.52 m from robot_1: within 0.47 + 0.1
        (5.0, "robot_0", "on_wall", [(0.85, 0.15)]),              # 0.05 m above the wall, no block there
        (5.0, "robot_0", "on_block", [(0.5, 0.15)]),              # touches the wall, but on the block
        (5.0, "robot_0", "clean", [(0.85, 0.25), (2.6, 2.0)]),    # 0.15 m from the wall, 0.6 m from robot_1
        (5.0, "robot_1", "own_pose", [(2.0, 2.0)]),               # the source's own pose: not another robot
        (9.0, "robot_0", "robot_moved_away", [(2.0, 2.0)]),       # robot_1 left (2.0, 2.0) by then (x = 2.8)
    ]
    evidence = {}
    kinds = classify_obstacles(groups, cells, tracks, 0.47, walls, blocks, evidence=evidence)
    assert kinds == {0: (True, False), 1: (False, True), 2: (False, False), 3: (False, False),
                     4: (False, False), 5: (False, False)}
    assert evidence == {0: {"robot": [5.0, 2.52, 2.0, "robot_1", 0.52]}, 1: {"wall": [5.0, 0.85, 0.15]}}


def test_classify_per_merged_group():
    tracks = {"robot_0": [(0.0, 5.0, 5.0), (10.0, 5.0, 5.0)], "robot_1": [(0.0, 2.0, 2.0), (10.0, 2.0, 2.0)]}
    cells = [(1.0, "robot_0", "a", [(8.0, 8.0)]), (2.0, "robot_0", "b", [(2.1, 2.0)])]
    assert classify_obstacles([["a", "b"]], cells, tracks, 0.47, None) == {0: (True, False)}


def test_facility_block_faces_touch_walls_but_are_not_walls():
    """Why blocks are excluded: block_right reaches 0.1 m into both corridor walls, so a cell of its
    face at the corridor's side lies within 0.1 m of the map's wall."""
    f = load_facility(os.path.join(WORLDS, "goals.yaml"))
    block = f["blocks"]["block_right"]
    x0, _y0, _x1, _y1 = f["corridors"]["right"]
    # the facility's walls as the map has them: solid left of the corridor (x < 10.4) at y 3.4..6.8
    data = [100 if (10.0 + (ix + 0.5) * 0.05) < x0 else 0 for _iy in range(20) for ix in range(40)]
    walls = OccupancyIndex(40, 20, 0.05, 10.0, 4.6, data)
    face_cell = (x0 + 0.025, 4.975)                      # the block's lower face, first cell in the corridor
    assert walls.near(*face_cell, 0.1)
    kinds = classify_obstacles([["b"]], [(1.0, "robot_0", "b", [face_cell])], {}, 0.47, walls, [block_rect(block)])
    assert kinds == {0: (False, False)}


# --- bytes through the broker ($SYS) -------------------------------------------------------------

def test_sys_message_bytes():
    assert sys_message_bytes("$SYS/broker/bytes/sent", b"100") == 1 + 1 + 2 + 22 + 3
    assert sys_message_bytes("t", b"x" * 200) == 1 + 2 + 2 + 1 + 200     # remaining length needs 2 bytes


def test_broker_bytes_per_robot_per_simulated_minute():
    base = (1000, 500, 100.0)                # sent, received, simulated s
    end = (61000, 12500, 220.0)              # 2 simulated minutes later
    b = broker_bytes(base, end, 5, own_bytes=0)
    assert (b["sent"], b["received"], b["total"]) == (60000, 12000, 72000)
    assert b["sim_minutes"] == pytest.approx(2.0)
    assert b["per_robot_per_minute"] == pytest.approx(72000 / 5 / 2.0)
    mine = broker_bytes(base, end, 5, own_bytes=1000)     # the bench's own $SYS subscription is not the fleet's
    assert mine["sent"] == 59000 and mine["total"] == 71000


def test_broker_bytes_refuses_a_restarted_broker():
    with pytest.raises(ValueError):
        broker_bytes((1000, 500, 0.0), (10, 600, 60.0), 2)


# --- the settings printed beside the table --------------------------------------------------------

def load_bench_fleet():
    path = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scripts", "bench_fleet")
    loader = importlib.machinery.SourceFileLoader("bench_fleet_script", path)
    spec = importlib.util.spec_from_loader(loader.name, loader)
    module = importlib.util.module_from_spec(spec)
    loader.exec_module(module)
    return module


def test_non_defaults_lists_only_what_differs():
    bf = load_bench_fleet()
    got = bf.nav_non_defaults({"controller_frequency": 10.0, "stuck_feedback_on_local_failure": False,
                               "global_costmap": {"raytrace_range": 2.5, "obstacle_range": 2.5},
                               "sharing": {"plan_trigger": False, "trigger_radius": 1.0}})
    assert got == [("controller_frequency", 10.0, 20.0), ("global_costmap/raytrace_range", 2.5, 3.0),
                   ("sharing/plan_trigger", False, True), ("sharing/trigger_radius", 1.0, None)]


def test_bench_defaults_are_the_launch_files():
    bf = load_bench_fleet()
    assert float(bf.launch_defaults()["obstacle_duration"]) == 1200.0
    args = bf.make_parser().parse_args([])
    assert args.obstacle_duration == 1200 and len(args.seed) >= 3
    assert bf.non_defaults(args)[-1].startswith("bench: ")            # only the bench's own settings line
    lines = bf.non_defaults()
    assert not any("obstacle_duration" in line or "stuck_feedback" in line for line in lines)


def test_thesis_nav_params_are_printed_as_non_defaults():
    bf = load_bench_fleet()
    path = os.path.join(rospkg.RosPack().get_path("fleet_launch"), "config", "fleet_nav_thesis.yaml")
    args = bf.make_parser().parse_args(["--host", "fleet_sim", "--nav-params", path])
    lines = bf.non_defaults(args)
    assert lines[0].startswith("nav_params: " + path)
    assert "move_base stuck_feedback_on_local_failure: True (default False)" in lines
    assert "move_base stuck_feedback_on_local_failure: True (default False)" not in bf.non_defaults()


def bench_row(n, sharing, seed, times):
    return (n, sharing, seed, {"time_to_goal": dict(("robot_%d" % i, t) for i, t in enumerate(times)),
                               "time_mean": sum(times) / len(times)})


def test_chart_draws_each_complete_n_with_bars_as_tall_as_the_times(tmp_path):
    bf = load_bench_fleet()
    rows = [bench_row(2, True, 1, [50.0, 60.0]), bench_row(2, False, 1, [70.0, 70.0]),
            bench_row(2, True, 2, [54.0, 56.0]), bench_row(2, False, 2, [68.0, 72.0]),
            bench_row(5, True, 1, [40.0] * 5), (5, False, 1, None),      # a run that gave no result
            bench_row(10, True, 3, [45.0] * 10)]                         # no sharing-off run
    path = str(tmp_path / "chart.png")
    drawn = bf.chart(rows, path, "test")
    assert set(drawn) == {(2, True), (2, False)}, "only N with a seed that has both runs is drawn"
    (_x0, top_on, _x1, bottom), (_a, top_off, _b, _c) = drawn[(2, True)], drawn[(2, False)]
    assert (bottom - top_on) / (bottom - top_off) == pytest.approx(55.0 / 70.0, rel=0.02)
    from PIL import Image
    with Image.open(path) as img:
        assert img.size[0] > 0 and img.getpixel((int(_x0) + 2, int(bottom) - 2)) != (255, 255, 255)


def test_chart_refuses_rows_without_a_complete_seed(tmp_path):
    bf = load_bench_fleet()
    with pytest.raises(ValueError, match="no N with a seed"):
        bf.chart([bench_row(2, True, 1, [50.0]), (2, False, 1, None)], str(tmp_path / "c.png"), "test")
    assert bf.draw_chart([(2, True, 1, None)], str(tmp_path / "c.png"), bf.make_parser().parse_args([])) == 1
    assert not (tmp_path / "c.png").exists()


def test_on_stage_the_non_defaults_are_the_tutorials_multi_robot_rate_and_what_the_bench_changed():
    bf = load_bench_fleet()
    lines = bf.non_defaults(bf.make_parser().parse_args(["--host", "stage", "--layout", "deadend", "--speedup", "2",
                                                          "--obstacle-duration", "600"]))
    assert lines[0].startswith("move_base controller_frequency: 10")
    assert any(line.startswith("obstacle_duration: 600 s") for line in lines)
    assert any(line.startswith("Stage speedup 2 (N = 2, 5, 10)") for line in lines)
    real_time = bf.make_parser().parse_args(["--host", "stage", "--robots", "2", "5"])
    assert not any("speedup" in line for line in bf.non_defaults(real_time))
    by_default = bf.non_defaults(bf.make_parser().parse_args(["--host", "stage"]))
    assert "Stage speedup 1 (N = 2, 5), 0.5 (N = 10) (real time: 1; the factor each run reached is in the table)" \
        in by_default


def test_the_on_off_interval_is_students_t_over_the_seeds_and_none_for_one_seed():
    bf = load_bench_fleet()
    mean, low, high = bf.ratio_interval([0.8, 0.9, 1.0])
    assert mean == pytest.approx(0.9)
    assert (high - mean) == pytest.approx(4.302653 * 0.1 / math.sqrt(3), rel=1e-4)   # t(0.975, 2 df)
    assert low == pytest.approx(2 * mean - high)
    mean, low, high = bf.ratio_interval([0.8])
    assert mean == 0.8 and math.isnan(low) and math.isnan(high)
    assert math.isnan(bf.ratio_interval([float("nan")])[0])


def test_layout_all_writes_one_table_per_layout_and_summarize_reads_them_back(tmp_path, capsys):
    bf = load_bench_fleet()
    assert bf.per_layout_path("/o/fleet.md", "deadend", True) == "/o/fleet_deadend.md"
    assert bf.per_layout_path("/o/fleet.md", "deadend", False) == "/o/fleet.md"
    assert bf.per_layout_path(None, "deadend", True) is None
    fields = {"recoveries": 0, "stuck": 0, "entered_blocked_corridor": 0, "reached": 2, "time_p95": 1.0,
              "distance_m": 1.0, "latency_ms_p50": 1.0, "latency_ms_p99": 1.0, "latency_ms": [1.0]}
    for layout, on, off in (("facility", 50.0, 100.0), ("corridors", 90.0, 100.0)):
        for sharing, t in ((True, on), (False, off)):
            row = dict(fields, time_to_goal={"robot_0": t, "robot_1": t}, time_mean=t)
            with open(str(tmp_path / ("%s_n2_s1_%s.json" % (layout, "on" if sharing else "off"))), "w") as f:
                json.dump(row, f)
    (tmp_path / "notes_n2.json").write_text("{}")                  # not a run: ignored
    args = bf.make_parser().parse_args(["--summarize", str(tmp_path), "--table", str(tmp_path / "fleet.md")])
    assert bf.summarize(None, args) == 0
    facility = (tmp_path / "fleet_facility.md").read_text()
    corridors = (tmp_path / "fleet_corridors.md").read_text()
    assert "| 2 | 1 | 50.0 ± 0.0 | 100.0 ± 0.0 | 0.50 |" in facility, facility
    assert "| 2 | 1 | 90.0 ± 0.0 | 100.0 ± 0.0 | 0.90 |" in corridors, corridors
    assert "layout facility" in facility and "layout corridors" in corridors
    out = capsys.readouterr().out
    assert out.index("## facility world") < out.index("## corridors world")


def test_the_latency_cell_states_n_and_says_why_below_30():
    bf = load_bench_fleet()
    r = {"latency_ms": [1.0] * 28, "latency_missed": 2, "latency_ms_p50": 1.0, "latency_ms_p99": math.inf}
    assert bf.latency_cell(r) == "1.0 / inf (n = 30, 2 lost)"
    r["latency_missed"] = 1
    assert bf.latency_cell(r).startswith("1.0 / inf (n = 29 < 30: only 29 obstacle x peer pairs")


def test_a_pair_that_never_arrived_makes_the_p99_infinite_not_smaller():
    from fleet_tests.scenario import percentile
    assert percentile([1.0] * 99 + [math.inf], 50) == 1.0
    assert math.isinf(percentile([1.0] * 98 + [math.inf] * 2, 99))
    assert math.isinf(percentile([math.inf], 99))


def full_row(times, reached, recoveries=0, crossed=0, precision=1.0, factor=1.0):
    return {"time_to_goal": dict(("robot_%d" % i, t) for i, t in enumerate(times)),
            "time_mean": sum(times) / len(times) if times else float("nan"), "reached": reached,
            "recoveries": recoveries, "entered_blocked_corridor": crossed, "realtime_factor": factor,
            "ground_truth": {"precision": precision, "recall": {"block": 0.9}}}


def test_the_overview_has_one_row_per_world_and_n_pooled_over_complete_seeds():
    bf = load_bench_fleet()
    deadend = [(2, True, 1, full_row([40.0], 1, 4, 1)), (2, False, 1, full_row([], 0, 8, 2)),
               (10, True, 1, full_row([30.0, 34.0], 2, 0, 1, factor=0.5)), (10, False, 1, full_row([60.0], 1, 4, 2)),
               (10, True, 2, full_row([32.0], 1, factor=0.49)), (10, False, 2, full_row([64.0], 1)),
               (10, True, 3, full_row([1.0], 1)), (10, False, 3, None)]            # seed 3 incomplete: left out
    corridors = [(5, True, 1, None), (5, False, 1, full_row([50.0], 1))]
    lines = bf.overview({"deadend": deadend, "corridors": corridors})
    assert lines[2] == ("| deadend | 2 | 1 | 1.00 | 1/2 / 0/2 | 40.0 ± 0.0 / - | - | - (no robot arrived without sharing) "
                        "| 4 / 8 | 1 / 2 | 1.000 | 0.900 |")
    mean_on, mean_off = 32.0, 62.0
    assert lines[3].startswith("| deadend | 10 | 1 2 | 0.49 | 3/20 / 2/20 | %.1f ± 2.0 / %.1f ± 2.8 | %.2f | "
                               % (mean_on, mean_off, mean_on / mean_off)), lines[3]
    assert "| 0 / 4 | 1 / 2 |" in lines[3]                  # the sums over both seeds
    assert lines[4] == "| corridors | 5 | none complete | | | | | | | | | |"


def test_a_chart_says_where_no_robot_arrived_instead_of_leaving_the_bar_out_silently(tmp_path):
    bf = load_bench_fleet()
    rows = [(2, True, 1, full_row([50.0], 1)), (2, False, 1, full_row([], 0)),
            (10, True, 1, full_row([30.0], 1, factor=0.5)), (10, False, 1, full_row([60.0], 1, factor=0.5))]
    path = str(tmp_path / "c.png")
    drawn = bf.chart(rows, path, "test")
    assert set(drawn) == {(2, True), (10, True), (10, False)}
    from PIL import Image
    img = Image.open(path).convert("RGB")
    x0, _top, x1, bottom = drawn[(2, True)]
    slot = img.crop((int(x1) + 14, int(bottom) - 32, int(x1) + 70, int(bottom) - 2))   # where the off bar would be
    assert any(p == (0, 0, 0) for p in slot.getdata()), "no text where the sharing-off bar is missing"
