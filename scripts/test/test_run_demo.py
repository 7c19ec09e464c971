"""make demo checks itself (scripts/run_demo.py report_checks): a passing run printed 4-5
`[ERROR] ... Got a transition callback on a goal handle that we're not tracking` lines, took its
RViz screenshot before anything was shared, left Test 3's robot_0 goal out of the metrics table
and said robots got stuck where the figures said 0 (issue 31). Each check here is fed one such
fault and must name it; a clean run must pass. No ROS needed: the results are made up."""
import argparse
import copy
import importlib.util
import os

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def load_runner():
    spec = importlib.util.spec_from_file_location("run_demo", os.path.join(ROOT, "scripts", "run_demo.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


demo = load_runner()

ERROR = "[ERROR] [1795647310.009625, 29.400000]: Got a transition callback on a goal handle that we're not tracking"


def args(**kw):
    base = dict(tests=[1, 2, 3], no_rviz=False, no_vda=False)
    base.update(kw)
    return argparse.Namespace(**base)


def robot(shared=0, corridors=()):
    return {"stuck": 0, "recoveries": 0, "shared": shared, "updates_sent": 0, "received": 0,
            "corridors": list(corridors), "distance_m": 1.0, "bytes_published": "0"}


def result(test, goals, shares, r0, r1, steps=2):
    return {"test": test, "goals": [{"robot": rb, "goal": g, "state": "SUCCEEDED", "seconds": 10.0, "text": ""}
                                    for rb, g in goals],
            "shares": [{"robot": "robot_0", "t": 30.0 + k, "uuid": "u%d" % k, "block": b, "distance_m": 1.5,
                        "cells": 10} for k, b in enumerate(shares)],
            "steps": [{"step": k, "caption": "c", "t": 10.0 * k, "png": "test%d_step%02d.png" % (test, k),
                       "trails": True} for k in range(1, steps + 1)],
            "events": [],
            "metrics": {"robots": {"robot_0": r0, "robot_1": r1}, "latency_ms_p50": 4.0, "latency_ms_p99": 5.0,
                        "lists_identical": True, "obstacles_at_end": 1},
            "rviz": None, "vda": None}


def output(goals):
    return "".join("[INFO] [1.0, 2.0]: scenario: %s sent to %s (1.00, 2.00)\n" % g for g in goals)


GOALS = {1: [("robot_1", "wait_1"), ("robot_0", "orange"), ("robot_1", "start_1"), ("robot_1", "purple")],
         2: [("robot_0", "orange"), ("robot_1", "purple")],
         3: [("robot_0", "orange"), ("robot_1", "red"), ("robot_1", "start_1")]}


def clean_run(tmp_path):
    results = [
        result(1, GOALS[1], ["block_right", "block_middle"], robot(2, ["left"]), robot(0, ["left"])),
        result(2, GOALS[2], ["block_right"], robot(1, ["right"]), robot(0, ["right"])),
        result(3, GOALS[3], ["block_right"], robot(1), robot(0)),
    ]
    results[0]["rviz"] = {"png": "rviz.png", "step": 4, "caption": "c", "problems": [], "marker_pixels": 400,
                          "both_blocks_held": True,
                          "obstacles": {"robot_0": ["u0 from robot_0", "u1 from robot_0"]}}
    results[0]["vda"] = {"version": "2.1.0", "robot": "robot_0", "blocked_edges": {"purple-red": "u0"},
                         "state_latency_s": 0.1, "area_latency_s": 0.2, "area_cells": 100, "withdraw_latency_s": 0.2,
                         "log": ["  0.00 s  MC -> robot  order           order demo-order-1"]}
    for r in results:
        for s in r["steps"]:
            (tmp_path / s["png"]).write_bytes(b"png")
    outputs = {t: output(GOALS[t]) for t in (1, 2, 3)}
    return results, outputs


def test_a_clean_run_passes(tmp_path):
    results, outputs = clean_run(tmp_path)
    assert demo.report_checks(results, outputs, args(), str(tmp_path)) == []


def test_an_error_line_fails_the_run(tmp_path):
    results, outputs = clean_run(tmp_path)
    outputs[3] += ERROR + "\n"
    problems = demo.report_checks(results, outputs, args(), str(tmp_path))
    assert len(problems) == 1 and "Test 3 printed" in problems[0] and "not tracking" in problems[0]


def test_an_error_line_of_the_fleets_launch_fails_the_run(tmp_path):
    results, outputs = clean_run(tmp_path)
    launch = {1: "process[robot_0/move_base-5]: started with pid [1]\n[ERROR] [1.0]: robot_0/move_base died\n"}
    problems = demo.report_checks(results, outputs, args(), str(tmp_path), launch)
    assert problems == ["Test 1, the fleet's roslaunch printed: [ERROR] [1.0]: robot_0/move_base died"]


def test_error_lines_are_rospy_and_roscpp_errors_and_tracebacks():
    text = "\n".join([ERROR, "[ INFO] [1.0]: fine", "[INFO] [1.0, 2.0]: scenario: errors=[] in the state",
                      "[FATAL] [1.0]: gone", "Traceback (most recent call last):", "[WARN] [1.0]: careful",
                      "[demo test 1] step 1: the ERROR-free start"])
    assert demo.error_lines(text) == [ERROR, "[FATAL] [1.0]: gone", "Traceback (most recent call last):"]


def test_a_goal_missing_from_the_table_fails(tmp_path):
    results, outputs = clean_run(tmp_path)
    results[2]["goals"] = [g for g in results[2]["goals"] if g["robot"] != "robot_0"]   # the old Test 3
    problems = demo.report_checks(results, outputs, args(), str(tmp_path))
    assert len(problems) == 1 and problems[0].startswith("Test 3: goals sent") and "robot_0 orange" in problems[0]


def test_rviz_screenshot_without_markers_or_before_sharing_fails(tmp_path):
    results, outputs = clean_run(tmp_path)
    results[0]["rviz"]["marker_pixels"] = 0
    assert any("marker pixels" in p for p in demo.report_checks(results, outputs, args(), str(tmp_path)))
    results[0]["rviz"]["marker_pixels"] = 400
    results[0]["rviz"]["both_blocks_held"] = False      # the old screenshot: step 2, nothing shared yet
    assert any("before every robot held both blocks" in p
               for p in demo.report_checks(results, outputs, args(), str(tmp_path)))
    results[0]["rviz"] = None          # never taken: no step had both blocks held
    assert any("no RViz screenshot" in p for p in demo.report_checks(results, outputs, args(), str(tmp_path)))
    assert demo.report_checks(results, outputs, args(no_rviz=True), str(tmp_path)) == []


def test_a_frame_without_trails_fails(tmp_path):
    results, outputs = clean_run(tmp_path)
    results[1]["steps"][0]["trails"] = False
    problems = demo.report_checks(results, outputs, args(), str(tmp_path))
    assert problems == ["Test 2 step 1: the frame has no trails"]


def test_a_caption_the_figures_contradict_fails(tmp_path):
    results, outputs = clean_run(tmp_path)
    results[0]["metrics"]["robots"]["robot_1"]["corridors"] = ["right"]
    problems = demo.report_checks(results, outputs, args(), str(tmp_path))
    assert len(problems) == 1 and "left corridor" in problems[0]


def test_a_failed_vda_exchange_fails(tmp_path):
    results, outputs = clean_run(tmp_path)
    results[0]["vda"] = {"error": "master control: no blocked edge in robot_0's state within 10 s", "log": []}
    problems = demo.report_checks(results, outputs, args(), str(tmp_path))
    assert problems == ["VDA 5050 exchange: master control: no blocked edge in robot_0's state within 10 s"]
    assert demo.report_checks(results, outputs, args(no_vda=True), str(tmp_path)) == []


def test_the_report_says_what_the_figures_say(tmp_path):
    results, outputs = clean_run(tmp_path)
    demo.report(copy.deepcopy(results), str(tmp_path), 100.0, [], [])
    text = (tmp_path / "report.md").read_text()
    assert "stuck once" not in text and "magenta markers" not in text
    # every goal in the table, Test 3's robot_0 too
    row = [line for line in text.splitlines() if line.startswith("| 3 | robot_0 |")][0]
    assert "orange ok 10" in row
    assert "| stuck_feedback | recoveries |" in text
    assert "robot_1 drove through the left corridor" in text
    assert "stuck_feedback events: 0, recovery behaviours: 0" in text
    assert "## VDA 5050 exchange" in text and "`purple-red`" in text and "order demo-order-1" in text
    assert "step 4" in text and "Both blocks shared: robot_0 holds u0 from robot_0, u1 from robot_0" in text
    demo.report(results, str(tmp_path), 100.0, [], ["Test 3 printed: " + ERROR])
    assert "**Checks that failed:**" in (tmp_path / "report.md").read_text()
