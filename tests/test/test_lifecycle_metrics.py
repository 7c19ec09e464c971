"""The lifecycle bench's metrics (fleet_tests.lifecycle, tests/scripts/bench_lifecycle) on synthetic runs."""
import importlib.machinery
import importlib.util
import os
from types import SimpleNamespace

from fleet_tests.lifecycle import costmap_free_at, emptied_at, end_to_last_drop, found_block_at, present_after

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
             "verification": {"spread_s": None, "costmaps_free": {"robot_0": False, "robot_1": False},
                              "receipts": {"end_to_last_drop_s": None, "end_to_last_drop_wall_s": None}}}
    cleared = {"remove_after_s": 30.0, "stale_detour": False, "stale_detour_s": 0.0,
               "verification": {"spread_s": 0.4, "costmaps_free": {"robot_0": True, "robot_1": True},
                                "receipts": {"end_to_last_drop_s": 0.1, "end_to_last_drop_wall_s": 0.0123}}}
    stale.update(follower_time_to_goal=80.0, follower_distance_m=40.0)
    # the same seed's follower with sharing off knew nothing and drove the short way
    reference = {"follower_time_to_goal": 50.0, "follower_distance_m": 26.0}
    lines = bench.removed_table([(150, 1, stale), (150, 2, cleared), (630, 1, None)], {(150, 1): reference})
    assert "| 120 s | 1/2 | +30.0 s, +14.0 m (1 of them) | 0.40 (1/2 runs) | 0.10 / 12 (1/2 runs) | 1/2 |" in lines
    assert "| 630 s | no result | | | | |" in lines
    # a stale detour without a sharing-off run to compare with says so; no detour says none
    lines = bench.removed_table([(150, 1, stale)])
    assert "| 120 s | 1/1 | no sharing-off run to compare with |" in lines[-1]
    # a run from before the receipts (no "receipts" in its verification) is not measured, not an error
    old = {"remove_after_s": 30.0, "stale_detour": False, "stale_detour_s": 0.0,
           "verification": {"spread_s": 1.1, "costmaps_free": {"robot_0": True, "robot_1": True}}}
    assert "| 120 s | 0/1 | none | 1.10 (1/1 runs) | not measured | 1/1 |" in bench.removed_table([(150, 1, old)])


# Receipt timelines: (sim time, wall time, kind, marked, cleared, version, source).
def update(sim, wall, marked=(), cleared=(), version=1, source="robot_0"):
    return (sim, wall, "update", tuple(marked), tuple(cleared), version, source)


def test_present_cells_follow_the_stamp_rule_whatever_the_order():
    share = ((1, 2, 3), (), 1, "robot_0")
    clear = ((), (1, 2, 3), 2, "robot_0")
    assert present_after([share]) == {1, 2, 3}
    assert present_after([share, clear]) == set()
    assert present_after([clear, share]) == set()          # the older mark arriving late stays cleared
    assert present_after([share, ((), (2,), 2, "robot_1"), ((2,), (), 3, "robot_0")]) == {1, 2, 3}  # newer mark
    assert present_after([((5,), (5,), 1, "robot_0")]) == set()                # a tie: absent wins


def test_an_obstacle_is_emptied_by_the_update_that_clears_its_last_present_cell():
    events = [(10.0, "update", (1, 2), (), 1, "robot_0"), (20.0, "update", (), (1,), 2, "robot_0"),
              (20.1, "update", (), (2,), 3, "robot_0"), (20.5, "update", (), (2,), 3, "robot_0")]
    assert emptied_at(events) == 2
    assert emptied_at(events, after=20.2) is None          # emptied before `after`: not this time
    assert emptied_at(events[:2]) is None
    assert emptied_at([(5.0, "update", (1,), (), 1, "robot_0"), (9.0, "expired", (), (), 0, "")]) == 1
    assert emptied_at([(9.0, "expired", (), (), 0, "")]) is None     # nothing was shown
    # cleared, marked again (the block is back), cleared again: the first emptying at or after `after`
    again = events[:3] + [(30.0, "update", (2,), (), 4, "robot_1"), (40.0, "update", (), (2,), 5, "robot_0")]
    assert emptied_at(again, after=25.0) == 4


def test_end_to_last_drop_runs_from_the_clearers_handler_to_the_last_layer():
    share = update(100.0, 1000.0, marked=(1, 2))
    # robot_0 saw the place free: its layer cleared cell 1, then cell 2; its handler sent both out
    handler_0 = [share, update(200.0, 1100.00, cleared=(1,), version=2),
                 update(200.5, 1100.10, cleared=(2,), version=3)]
    # robot_1's handler got them over MQTT a little later
    handler_1 = [share, update(200.1, 1100.02, cleared=(1,), version=2),
                 update(200.6, 1100.13, cleared=(2,), version=3)]
    layer_0 = [share, update(200.0, 1099.99, cleared=(1,), version=2), update(200.4, 1100.09, cleared=(2,), version=3)]
    layer_1 = [share, update(200.1, 1100.03, cleared=(1,), version=2), update(200.7, 1100.15, cleared=(2,), version=3)]
    got = end_to_last_drop({"handler": {"robot_0": handler_0, "robot_1": handler_1},
                            "layer": {"robot_0": layer_0, "robot_1": layer_1}}, after=150.0)
    assert got["clearer"] == "robot_0" and got["ended"] == 200.5
    assert got["dropped"] == {"robot_0": 200.4, "robot_1": 200.7}
    assert abs(got["end_to_last_drop_s"] - 0.2) < 1e-9
    assert abs(got["end_to_last_drop_wall_s"] - 0.05) < 1e-6
    # robot_1's layer never dropped it: no figure
    stuck = end_to_last_drop({"handler": {"robot_0": handler_0, "robot_1": handler_1},
                              "layer": {"robot_0": layer_0, "robot_1": [share]}}, after=150.0)
    assert stuck["dropped"]["robot_1"] is None and stuck["end_to_last_drop_s"] is None
    # an expiry on robot_1's layer drops it too
    expired = [share, (200.9, 1100.2, "expired", (), (), 0, "")]
    got = end_to_last_drop({"handler": {"robot_0": handler_0, "robot_1": handler_1},
                            "layer": {"robot_0": layer_0, "robot_1": expired}})
    assert abs(got["end_to_last_drop_s"] - 0.4) < 1e-9
    # nobody ended it
    none = end_to_last_drop({"handler": {"robot_0": [share]}, "layer": {"robot_0": [share]}})
    assert none["clearer"] is None and none["ended"] is None and none["end_to_last_drop_s"] is None


def test_the_clearer_is_the_source_of_the_emptying_update_not_the_first_receipt():
    """One observer receives robot_1's from_fleet copy of robot_0's update before robot_0's own to_fleet message
    (two connections): robot_0 still cleared it, and the figure runs from robot_0's handler."""
    share = update(100.0, 1000.0, marked=(1,))
    last = dict(cleared=(1,), version=2, source="robot_0")
    got = end_to_last_drop({"handler": {"robot_0": [share, update(216.1, 1100.010, **last)],
                                        "robot_1": [share, update(216.0, 1100.008, **last)]},
                            "layer": {"robot_0": [share, update(216.0, 1100.005, **last)],
                                      "robot_1": [share, update(216.1, 1100.012, **last)]}})
    assert got["clearer"] == "robot_0" and got["ended"] == 216.1
    assert abs(got["end_to_last_drop_s"]) < 1e-9 and abs(got["end_to_last_drop_wall_s"] - 0.002) < 1e-6
