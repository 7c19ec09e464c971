"""The lifecycle bench's metrics (fleet_tests.lifecycle, tests/scripts/bench_lifecycle) on synthetic runs."""
import importlib.machinery
import importlib.util
import os
from types import SimpleNamespace

from fleet_tests.lifecycle import costmap_free_at, found_block_at

BLOCK = {"pose": [12.9, 6.0, 0.0], "size": [2.8, 0.3]}


def load_script():
    path = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scripts", "bench_lifecycle")
    loader = importlib.machinery.SourceFileLoader("bench_lifecycle_script", path)
    spec = importlib.util.spec_from_loader(loader.name, loader)
    module = importlib.util.module_from_spec(spec)
    loader.exec_module(module)
    return module


def test_the_block_is_found_when_the_track_first_comes_within_reach():
    track = [(0.0, 13.6, 1.0), (5.0, 13.6, 3.0), (6.0, 13.6, 3.4), (7.0, 13.6, 3.5)]
    assert found_block_at(track, BLOCK, 2.5) == 6.0     # 5.85 - 3.4 = 2.45 m from the face
    assert found_block_at(track[:2], BLOCK, 2.5) is None


def grid(lethal_at=None):
    info = SimpleNamespace(resolution=0.05, width=400, height=300, origin=SimpleNamespace(
        position=SimpleNamespace(x=0.0, y=0.0)))
    data = [0] * (400 * 300)
    if lethal_at:
        x, y = lethal_at
        data[int(y / 0.05) * 400 + int(x / 0.05)] = 100
    return SimpleNamespace(info=info, data=data)


def test_a_costmap_is_free_where_no_cell_of_the_obstacle_is_lethal():
    cells = [(12.0, 5.825), (12.5, 5.825)]
    assert costmap_free_at(grid(), cells) is True
    assert costmap_free_at(grid(lethal_at=(12.5, 5.825)), cells) is False
    assert costmap_free_at(None, cells) is None


def run(entered, held=True, time=60.0, rediscovered=False):
    return {"follower_entered_blocked_corridor": entered, "follower_rediscovered": rediscovered,
            "held_at_dispatch": held, "follower_time_to_goal": time,
            "ground_truth": {"precision": 1.0, "recall": {"block_short": 0.9}}}


def test_the_sweep_table_counts_avoided_and_rediscovered_blocks_per_delay_and_mode():
    bench = load_script()
    rows = [(90, True, 1, run(False)), (90, True, 2, run(False)), (90, True, 3, None),
            (90, False, 1, run(True, held=False, rediscovered=True)), (900, True, 1, run(True, held=False))]
    lines = bench.sweep_table(rows)
    assert "| 90 s | on | 2/3 | 0/3 | 2/3 | 60.0 | 1.000 | 0.900 |" in lines
    assert "| 90 s | off | 0/1 | 1/1 | - | 60.0 | 1.000 | 0.900 |" in lines
    assert "| 900 s | on | 0/1 | 0/1 | 0/1 | 60.0 | 1.000 | 0.900 |" in lines
    assert "| 900 s | off | no result | | | | | |" in lines


def test_the_removed_table_counts_stale_detours_and_the_deletion_after_a_robot_looked():
    bench = load_script()
    stale = {"remove_after_s": 30.0, "stale_detour": True, "stale_detour_s": 120.0,
             "verification": {"spread_s": None, "costmaps_free": {"robot_0": False, "robot_1": False}}}
    cleared = {"remove_after_s": 30.0, "stale_detour": False, "stale_detour_s": 0.0,
               "verification": {"spread_s": 0.4, "costmaps_free": {"robot_0": True, "robot_1": True}}}
    lines = bench.removed_table([(150, 1, stale), (150, 2, cleared), (630, 1, None)])
    assert "| 120 s | 1/2 | 120 | 0.40 (1/2 runs) | 1/2 |" in lines
    assert "| 630 s | no result | | | |" in lines
