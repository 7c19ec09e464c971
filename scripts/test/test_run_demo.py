"""make demo checks itself (scripts/run_demo.py report_checks): a run without results, a robot missing from the
comparison, a missing or empty picture, a figure that prints as "nan", a report without the comparison, and an
ERROR line of ours in the launch logs each fail the run, named; a clean run passes, and the ERROR lines upstream
prints in a healthy loaded run (its tf lag) do not fail it. No ROS needed: the results are made up."""
import importlib.util
import os

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def load_runner():
    spec = importlib.util.spec_from_file_location("run_demo", os.path.join(ROOT, "scripts", "run_demo.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


demo = load_runner()
REPORT = "# Fleet demo\n\n| robot | sent |\n|---|---|\n| robot_0 | 0.0 |\n\n## The paths\n"
UPSTREAM_LAG = ("[ERROR] [1795905417.010253368, 48.000000000]: Extrapolation Error: Lookup would require extrapolation "
                "0.100000000s into the future.  Requested time 48.000000000 but the latest data is at time "
                "47.900000000, when looking up transform from frame [robot_0/odom] to frame [map]\n"
                "[ERROR] [1795905417.010333087, 48.000000000]: Global Frame: robot_0/odom Plan Frame size 146: map\n")


def pictures(tmp_path, size=5000):
    out = {}
    for name in ("paths", "timeline"):
        path = tmp_path / (name + ".png")
        path.write_bytes(b"\x89PNG" + b"x" * size)
        out[name] = str(path)
    return out


def checks(tmp_path, rows=({"robot": "robot_0"},), on=None, off=None, report=REPORT, logs="", size=5000):
    on = {"robots": 1} if on is None else on
    off = {"robots": 1} if off is None else off
    return demo.report_checks(list(rows), on, off, pictures(tmp_path, size), report, logs)


def test_a_clean_run_passes_also_with_upstreams_tf_lag_lines(tmp_path):
    assert checks(tmp_path) == []
    assert checks(tmp_path, logs=UPSTREAM_LAG) == []


def test_a_run_without_results_fails_naming_it(tmp_path):
    assert any("sharing off gave no result" in f for f in checks(tmp_path, off={}))


def test_a_robot_missing_from_the_comparison_fails(tmp_path):
    assert any("comparison has 1 robots, the runs 3" in f for f in checks(tmp_path, on={"robots": 3}))


def test_a_missing_or_empty_picture_fails(tmp_path):
    assert any("paths picture" in f for f in checks(tmp_path, size=10))
    failed = demo.report_checks([{"robot": "robot_0"}], {"robots": 1}, {"robots": 1},
                                {"paths": str(tmp_path / "none.png")}, REPORT, "")
    assert any("none.png is missing" in f for f in failed)


def test_a_figure_that_is_not_a_number_fails(tmp_path):
    failed = checks(tmp_path, report=REPORT + "| robot_1 | nan s / 4.0 s |\n")
    assert any("not a number: | robot_1 | nan s" in f for f in failed)


def test_a_report_without_the_comparison_fails(tmp_path):
    assert any("lacks the comparison" in f for f in checks(tmp_path, report="# Fleet demo\n"))


def test_an_error_line_of_ours_or_a_traceback_fails_the_run(tmp_path):
    ours = "[ERROR] [1.0, 2.0]: robot_0: handler crashed\n"
    assert any("handler crashed" in f for f in checks(tmp_path, logs=UPSTREAM_LAG + ours))
    assert any("Traceback" in f for f in checks(tmp_path, logs="Traceback (most recent call last):\n"))
    # an upstream line changed in any part is not exempt
    other = UPSTREAM_LAG.replace("robot_0/odom] to frame [map]", "robot_0/odom] to frame [robot_0/base_link]")
    assert checks(tmp_path, logs=other)


def test_move_base_giving_up_is_counted_as_upstreams_not_failed_on(tmp_path):
    abort = ("\x1b[31m[ERROR] [1795916543.067729142, 58.300000000]: Aborting because a valid control could not be "
             "found. Even after executing all recovery behaviors\x1b[0m\n")
    assert demo.error_lines(abort) == []
    assert demo.upstream_lines(abort) == {"move_base gave up on a goal (shown in the comparison)": 1}
    ours = "[ERROR] [1795916477.316450, 99.100000]: robot_0: could not withdraw the footprint of robot_2\n"
    assert demo.error_lines(abort + ours) == [ours.strip()]


def test_rotate_recovery_declining_to_turn_is_counted_as_upstreams_not_failed_on():
    """Seen in the run without sharing (robot_2 against block_right): move_base goes on to its next recovery."""
    declined = ("\x1b[31m[ERROR] [1795930358.923550183, 44.100000000]: Rotate recovery can't rotate in place because "
                "there is a potential collision. Cost: -1.00\x1b[0m\n")
    assert demo.error_lines(declined) == []
    assert demo.upstream_lines(declined) == {
        "move_base's rotate recovery declined to turn (a recovery the comparison counts)": 1}
    # another rotate_recovery ERROR is not exempt
    assert demo.error_lines(declined.replace("Rotate recovery can't rotate in place", "Rotate recovery crashed"))
