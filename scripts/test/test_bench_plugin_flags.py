"""bench_plugin_flags' reading of bench_plugin_cycle's table and its summary against issue 48's targets: the figures
come from the bench's own rows, and a median just over its target is printed NOT MET, one at the target met."""
import importlib.machinery
import importlib.util
import os

HERE = os.path.dirname(os.path.abspath(__file__))
SCRIPT = os.path.join(os.path.dirname(HERE), "bench_plugin_flags")


def load():
    loader = importlib.machinery.SourceFileLoader("bench_plugin_flags", SCRIPT)
    spec = importlib.util.spec_from_loader("bench_plugin_flags", loader)
    module = importlib.util.module_from_spec(spec)
    loader.exec_module(module)
    return module


flags = load()


def table(cycle_3m, scan_3m, cycle_30m, scan_30m):
    """Two cases of bench_plugin_cycle's output, as printed (a wall row with the case, a cpu row without)."""
    def verdict(ratio, target):
        return "%.3f (<=%.1f %s)" % (ratio, target, "met" if ratio <= target else "NOT MET")
    return [
        "bench_plugin_cycle: AMD EPYC, 2 cores; load 1.00 1.00 1.00",
        "case                       clock    up ms  ours ms        cycle ours/up  up scan ours scan         scan "
        "ours/up    window heap beyond up",
        "3 m / 2.5 m, 100 shared     wall    0.066    0.044 %20s    0.056    0.041 %20s   114x121 0.396 B/cell "
        "(<=1.0 met); counted 0.277" % (verdict(cycle_3m, 0.7), verdict(scan_3m, 0.9)),
        "                             cpu    0.066    0.044 %20s    0.056    0.041 %20s" % (
            verdict(cycle_3m - 0.01, 0.7), verdict(scan_3m - 0.01, 0.9)),
        "30 m / 30.0 m, 100 shared   wall    0.510    0.169 %20s    0.180    0.128 %20s   872x793 0.401 B/cell "
        "(<=1.0 met); counted 0.277" % (verdict(cycle_30m, 0.5), verdict(scan_30m, 0.9)),
        "                             cpu    0.509    0.169 %20s    0.179    0.128 %20s" % (
            verdict(cycle_30m, 0.5), verdict(scan_30m, 0.9)),
        "targets: ...: all met",
    ]


def test_rows_are_read_per_case_and_clock():
    rows = flags.parse_rows(table(0.661, 0.735, 0.333, 0.719))
    assert rows[("3 m / 2.5 m, 100 shared", "wall")] == {"cycle": 0.661, "scan": 0.735}
    assert rows[("3 m / 2.5 m, 100 shared", "cpu")] == {"cycle": 0.651, "scan": 0.725}
    assert rows[("30 m / 30.0 m, 100 shared", "cpu")] == {"cycle": 0.333, "scan": 0.719}
    assert len(rows) == 4


def test_a_row_marked_not_met_is_read_too():
    rows = flags.parse_rows(table(0.712, 0.95, 0.51, 0.92))
    assert rows[("3 m / 2.5 m, 100 shared", "wall")] == {"cycle": 0.712, "scan": 0.95}
    assert rows[("30 m / 30.0 m, 100 shared", "wall")] == {"cycle": 0.51, "scan": 0.92}


def test_ros_log_lines_are_not_the_table():
    assert flags.ROS_LOG.match("\x1b[0m[ INFO] [1795902317.25]: SharingLayer ours_2 (robot_0): ...")
    assert flags.ROS_LOG.match("[ WARN] [1795902317.25]: x")
    assert not flags.ROS_LOG.match("3 m / 2.5 m, 0 shared       wall    0.067")


def summary_of(*runs):
    lines, missed = flags.summarise([flags.parse_rows(table(*run)) for run in runs])
    return "\n".join(lines), missed


def test_medians_at_the_targets_are_met():
    text, missed = summary_of((0.70, 0.90, 0.50, 0.90), (0.70, 0.90, 0.50, 0.90), (0.60, 0.80, 0.40, 0.80))
    assert missed == []
    assert "NOT MET" not in text
    assert "median 0.700 (<=0.7 met; 3 of 3 runs met)" in text


def test_medians_just_over_the_targets_are_not_met_and_named():
    text, missed = summary_of((0.701, 0.901, 0.501, 0.901), (0.701, 0.901, 0.501, 0.901), (0.60, 0.80, 0.40, 0.80))
    assert "median 0.701 (<=0.7 NOT MET; 1 of 3 runs met)" in text
    assert "median 0.501 (<=0.5 NOT MET; 1 of 3 runs met)" in text
    assert "3 m / 2.5 m, 100 shared (wall) cycle" in missed
    assert "3 m / 2.5 m, 100 shared (wall) scan pass" in missed
    assert "30 m / 30.0 m, 100 shared (wall) cycle" in missed
    assert "30 m / 30.0 m, 100 shared (cpu) scan pass" in missed
    # the cpu rows of the 3 m case read 0.01 less: at their targets exactly, met
    assert "3 m / 2.5 m, 100 shared (cpu) cycle" not in missed


def test_one_run_over_a_target_does_not_move_a_median_under_it():
    text, missed = summary_of((0.65, 0.80, 0.40, 0.80), (0.95, 1.20, 0.90, 1.30), (0.66, 0.81, 0.41, 0.81))
    assert missed == []
    assert "0.650-0.950, median 0.660 (<=0.7 met; 2 of 3 runs met)" in text


def test_the_30_m_cases_have_the_tighter_cycle_target():
    assert flags.cycle_target("30 m / 30.0 m, 0 shared") == 0.5
    assert flags.cycle_target("3 m / 2.5 m, 0 shared") == 0.7
