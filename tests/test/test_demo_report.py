"""fleet_tests.demo_report: the demo's comparison of sharing on against off, from made-up runs (no ROS)."""
import math
import os

import pytest
from PIL import Image

from fleet_tests import demo_report as dr

CORRIDOR = [10.4, 3.4, 12.2, 6.8]


def run(sharing, times, entered, knew=None, shares=()):
    """A bench result of three robots sent 20 s apart from (13, 1) to (13, 9); robot_1 first."""
    order = ["robot_1", "robot_2", "robot_0"]
    dispatch = [{"robot": r, "sent_at": 10.0 + 20.0 * k} for k, r in enumerate(order)]
    tracks = {}
    for k, r in enumerate(order):
        t0 = 10.0 + 20.0 * k
        through = 11.3 if r in entered else 2.0  # the blocked corridor, or far left
        tracks[r] = [[t0, 13.0, 1.0], [t0 + 5, through, 4.0], [t0 + 10, through, 6.0], [t0 + 20, 13.0, 9.0]]
    return {"robots": 3, "sharing": sharing, "dispatch": dispatch,
            "time_to_goal": {r: t for r, t in zip(order, times) if t is not None},
            "tracks": tracks, "entered_per_robot": {r: (["right"] if r in entered else []) for r in order},
            "knew_block": knew or {}, "shares": list(shares), "realtime_factor": 0.98}


def rows_of(on, off):
    return dr.compare(on, off, "right")


ON = run(True, [60.0, 40.0, 42.0], {"robot_1"}, knew={"robot_1": 18.0, "robot_2": 18.1, "robot_0": 18.2},
         shares=[{"t": 18.0, "robot": "robot_1", "uuid": "u", "version": 1, "cells": [[11.3, 5.0], [11.35, 5.0]]}])
OFF = run(False, [60.0, 62.0, 61.0], {"robot_1", "robot_2", "robot_0"})


def test_the_comparison_lists_every_robot_in_dispatch_order_with_both_runs():
    rows = rows_of(ON, OFF)
    assert [r["robot"] for r in rows] == ["robot_1", "robot_2", "robot_0"]
    assert [r["sent"] for r in rows] == [0.0, 20.0, 40.0]
    assert [(r["time_on"], r["time_off"]) for r in rows] == [(60.0, 60.0), (40.0, 62.0), (42.0, 61.0)]
    assert [(r["entered_on"], r["entered_off"]) for r in rows] == [(True, True), (False, True), (False, True)]
    assert [r["knew_on"] for r in rows] == pytest.approx([8.0, 8.1, 8.2])
    t = dr.totals(rows)
    assert t["ratio"] == pytest.approx(142.0 / 183.0)
    assert (t["entered_on"], t["entered_off"], t["reached_on"], t["reached_off"]) == (1, 3, 3, 3)


def test_a_robot_that_did_not_arrive_is_said_so_and_left_out_of_the_ratio():
    off = run(False, [60.0, None, 61.0], {"robot_1", "robot_2", "robot_0"})
    rows = rows_of(ON, off)
    t = dr.totals(rows)
    assert t["both"] == 2 and t["ratio"] == pytest.approx(102.0 / 121.0)
    text = dr.markdown(rows, ON, off, ["controller_frequency 10"], {"paths": "p.png", "timeline": "t.png"}, "right")
    assert "| robot_2 | 20.0 | 40.0 s / not reached |" in text
    assert dr.numbers_missing(text) == []


def test_no_result_or_a_different_dispatch_is_an_error_naming_it():
    with pytest.raises(dr.ReportError, match="sharing off gave no result"):
        dr.compare(ON, None, "right")
    other = run(False, [1.0, 1.0, 1.0], set())
    other["dispatch"] = list(reversed(other["dispatch"]))
    with pytest.raises(dr.ReportError, match="dispatched differently"):
        dr.compare(ON, other, "right")


def test_the_report_leads_with_the_ratio_and_says_when_the_block_was_shared():
    text = dr.markdown(rows_of(ON, OFF), ON, OFF, ["controller_frequency 10"],
                       {"paths": "paths.png", "timeline": "timeline.png"}, "right")
    first = text.split("\n\n")[1]
    assert first.startswith("**With sharing the robots reached their goals in 0.78 × the time without**")
    assert "1 of 3 robots drove into the blocked right corridor with sharing, 3 without" in first
    assert "first shared by robot_1 8.0 s after the first dispatch (2 cells)" in text
    assert "![paths with sharing on and off](paths.png)" in text and "![timeline](timeline.png)" in text
    assert "- controller_frequency 10" in text and "0.98 with sharing" in text
    assert dr.numbers_missing(text) == []


def test_a_figure_that_is_not_a_number_is_found():
    assert dr.numbers_missing("| robot_0 | nan s |\nall fine\n| inf m |") == ["| robot_0 | nan s |", "| inf m |"]
    assert dr.numbers_missing("maintenance and financial") == []


def test_the_pictures_show_both_runs_the_block_and_the_shared_cells(tmp_path):
    from fleet_sim.map_io import OccupancyMap
    import numpy as np
    data = np.zeros((200, 320), dtype=np.int8)
    data[:, :4] = 100
    grid = OccupancyMap(data=data, resolution=0.05, origin=(0.0, 0.0, 0.0), image_path="")
    block = {"pose": [11.3, 5.1, 0.0], "size": [2.0, 0.3]}
    paths = dr.draw_paths(str(tmp_path / "paths.png"), grid, [block], ON, OFF)
    image = Image.open(paths).convert("RGB")
    assert image.size[0] > 2 * 600   # 30 px/m at 0.05 m per cell: 2 px per cell, 640 px per panel
    # the shared cell (11.3, 5.0) drawn in red in the left panel only, the block in black in both
    scale = max(1, int(round(30 * 0.05)))
    ppm = scale / 0.05
    x, y = int(11.33 * ppm), 64 + 200 * scale - int(5.0 * ppm)
    assert image.getpixel((x, y)) == dr.SHARED
    right = 320 * scale + 24
    assert image.getpixel((right + x, y)) != dr.SHARED
    bx, by = int(10.5 * ppm), 64 + 200 * scale - int(5.1 * ppm)   # the block, off every path
    assert image.getpixel((bx, by)) == dr.BLOCK and image.getpixel((right + bx, by)) == dr.BLOCK
    rows = rows_of(ON, OFF)
    spans = dict(dr.blocked_spans(ON, CORRIDOR))
    spans.update(dr.blocked_spans(OFF, CORRIDOR))
    assert spans[("robot_1", True)] == [(5.0, 10.0)]
    assert spans[("robot_2", True)] == []
    timeline = dr.draw_timeline(str(tmp_path / "timeline.png"), rows, ON, OFF, spans)
    assert os.path.getsize(timeline) > 1000
    assert math.isfinite(dr.totals(rows)["ratio"])


def test_a_world_with_two_blocked_corridors_counts_either():
    on = run(True, [50.0, 40.0, 42.0], set())
    on["entered_per_robot"]["robot_2"] = ["middle"]
    rows = dr.compare(on, OFF, ["middle", "right"])
    assert [r["entered_on"] for r in rows] == [False, True, False]
    text = dr.markdown(rows, on, OFF, [], {"paths": "p.png", "timeline": "t.png"}, ["middle", "right"])
    assert "drove into a blocked corridor (middle or right) with sharing" in text
