"""The flakiness runner (scripts/flaky_run.py) counts runs by their outcome and names each failure's
reason: nav_willow.test failed on a loaded machine in a clean-clone `make test`, and "10 of 10 under
load" has to be counted the same way each time (issue 28). No timing is asserted here."""
import pytest
import importlib.util
import json
import os
import stat
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def load_runner():
    spec = importlib.util.spec_from_file_location("flaky_run", os.path.join(ROOT, "scripts", "flaky_run.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


flaky = load_runner()

# What rosunit and rostest write (copied from real runs, system-out shortened).
PASSED_UNIT = """<?xml version="1.0" encoding="utf-8"?>
<testsuite errors="0" failures="0" name="unittest.suite.TestSuite" tests="1" time="63.199"><testcase
classname="__main__.NavWillow" name="test_1_far_goal_then_blocked_corridor" time="62.4551" /><system-out>&lt;![CDATA[
]]&gt;</system-out></testsuite>"""
PASSED_SUMMARY = """<?xml version="1.0" encoding="utf-8"?>
<testsuite errors="0" failures="0" name="unittest.suite.TestSuite" tests="1" time="65.594"><testcase
classname="rostest.runner.RosTest" name="testnav_willow" time="65.5934" /><system-out>&lt;![CDATA[
[ROSTEST]setup ...]]&gt;</system-out></testsuite>"""
FAILED_UNIT = """<?xml version="1.0" encoding="utf-8"?>
<testsuite errors="0" failures="1" name="unittest.suite.TestSuite" tests="1" time="0.151"><testcase
classname="__main__.NavWillow" name="test_1_far_goal_then_blocked_corridor" time="0.1508"><failure
type="AssertionError">False is not true : return goal not reached within 300 s of simulated time: ; pictures: wrote /tmp/a.png
  File "/usr/lib/python3.11/unittest/case.py", line 57, in testPartExecutor
    yield
  File "nav_willow_scenario.py", line 101, in test_1_far_goal_then_blocked_corridor
    self.assertTrue(finished, "return goal not reached within 300 s of simulated time: %s" % text)
</failure></testcase></testsuite>"""
TIMEOUT_SUMMARY = """<?xml version="1.0" encoding="utf-8"?>
<testsuite errors="1" failures="0" name="unittest.suite.TestSuite" tests="1" time="20.410"><testcase
classname="rostest.runner.RosTest" name="testnav_willow" time="20.4099"><error type="RLTestTimeoutException">max time [300.0s] allotted for test [nav_willow] of type [fleet_nav/nav_willow_scenario.py]
  File "/usr/lib/python3/dist-packages/roslaunch/launch.py", line 701, in run_test
    raise RLTestTimeoutException(
</error></testcase></testsuite>"""


def results(tmp_path, **files):
    """A rostest --results-base-dir with the given files under its package folder."""
    folder = tmp_path / "run"
    (folder / "fleet_nav").mkdir(parents=True)
    for name, text in files.items():
        (folder / "fleet_nav" / (name.replace("_", "-", 1) + ".xml")).write_text(text)
    return str(folder)


def test_a_passing_run_passes(tmp_path):
    folder = results(tmp_path, rosunit_nav_willow=PASSED_UNIT, rostest_test_nav_nav_willow=PASSED_SUMMARY)
    assert flaky.judge_folder(0, folder) == (True, [])


def test_a_failed_assertion_is_the_runs_reason(tmp_path):
    folder = results(tmp_path, rosunit_nav_willow=FAILED_UNIT, rostest_test_nav_nav_willow=PASSED_SUMMARY)
    passed, reasons = flaky.judge_folder(3, folder)
    assert not passed
    assert reasons == ["return goal not reached within 300 s of simulated time: ; pictures: wrote /tmp/a.png"]


def test_a_killed_test_takes_its_reason_from_rostests_summary(tmp_path):
    """rostest leaves the test's own file empty when the time limit kills it."""
    folder = results(tmp_path, rosunit_nav_willow="", rostest_test_nav_nav_willow=TIMEOUT_SUMMARY)
    passed, reasons = flaky.judge_folder(1, folder)
    assert not passed
    assert reasons == ["max time [300.0s] allotted for test [nav_willow] of type [fleet_nav/nav_willow_scenario.py]"]


def test_a_nonzero_exit_fails_a_run_whose_cases_all_passed(tmp_path):
    folder = results(tmp_path, rosunit_nav_willow=PASSED_UNIT, rostest_test_nav_nav_willow=PASSED_SUMMARY)
    assert flaky.judge_folder(1, folder) == (False, ["rostest exited 1"])


def test_no_results_is_a_failure(tmp_path):
    folder = tmp_path / "empty"
    folder.mkdir()
    assert flaky.judge_folder(0, str(folder)) == (False, ["no test results"])
    assert flaky.judge_folder(255, str(folder)) == (False, ["no test results"])


def test_an_unreadable_result_file_is_a_failure_naming_it(tmp_path):
    folder = results(tmp_path, rosunit_nav_willow="<testsuite><testcase", rostest_test_nav_nav_willow=PASSED_SUMMARY)
    passed, reasons = flaky.judge_folder(0, folder)
    assert not passed and len(reasons) == 1 and "unreadable result file" in reasons[0]


def test_reasons_are_one_line_each_and_not_repeated():
    assert flaky.failure_reason("<![CDATA[\nTraceback (most recent call last):\n  File \"x.py\", line 1\n"
                                "RuntimeError: node died\n]]>") == "node died"
    assert flaky.failure_reason("1 != 2 : far goal: aborted\n  File \"x\"") == "1 != 2 : far goal: aborted"
    assert flaky.failure_reason("") == "no reason given"
    case = ("a.b", "failed", "same")
    assert flaky.judge(1, [case, case], []) == (False, ["same"])


def run(index, passed, before=2.0, after=3.0, reasons=()):
    return {"index": index, "passed": passed, "reasons": list(reasons), "returncode": 0 if passed else 1,
            "wall_s": 1.0, "load_before": before, "load_after": after}


def test_the_summary_counts_passed_runs_and_states_the_load():
    runs = [run(1, True, 2.5, 3.1), run(2, False, 3.9, 4.4, ["r"]), run(3, True, 2.1, 2.2)]
    assert flaky.summary_line(runs) == "2 of 3 passed (1-min load average 2.1-4.4)"
    assert flaky.summary_line([run(1, True)] * 10).startswith("10 of 10 passed")
    line = flaky.run_line(runs[1], 3)
    assert line.startswith("run 2/3: FAILED") and line.endswith("\n    r")


FAKE_ROSTEST = """#!%s
# rostest stand-in: passes, then fails, then passes ... (a counter file beside it)
import os, sys
base = sys.argv[sys.argv.index("--results-base-dir") + 1]
counter = os.path.join(os.path.dirname(os.path.abspath(__file__)), "count")
n = int(open(counter).read()) if os.path.exists(counter) else 0
open(counter, "w").write(str(n + 1))
os.makedirs(os.path.join(base, "fleet_nav"))
open(os.path.join(base, "fleet_nav", "rosunit-nav_willow.xml"), "w").write(%r if n %% 2 else %r)
open(os.path.join(base, "fleet_nav", "rostest-nav_willow.xml"), "w").write(%r)
sys.exit(1 if n %% 2 else 0)
"""


def test_main_runs_the_test_n_times_and_prints_k_of_n(tmp_path, monkeypatch, capsys):
    fake = tmp_path / "bin" / "rostest"
    fake.parent.mkdir()
    fake.write_text(FAKE_ROSTEST % (sys.executable, FAILED_UNIT, PASSED_UNIT, PASSED_SUMMARY))
    fake.chmod(fake.stat().st_mode | stat.S_IEXEC)
    monkeypatch.setenv("PATH", "%s:%s" % (fake.parent, os.environ["PATH"]))
    out = tmp_path / "out"
    code = flaky.main(["--repeat", "3", "--load", "0", "--results", str(out), "fleet_nav", "nav_willow.test"])
    text = capsys.readouterr().out
    assert code == 1
    assert "2 of 3 passed" in text
    assert "run 2/3: FAILED" in text and "return goal not reached within 300 s of simulated time" in text
    summary = json.loads((out / "summary.json").read_text())
    assert [r["passed"] for r in summary["runs"]] == [True, False, True]
    assert summary["test"] == ["fleet_nav", "nav_willow.test"] and summary["load_processes"] == 0


def test_the_load_processes_are_ours_and_stopped():
    procs = flaky.start_load(1)
    try:
        assert len(procs) == 1 and procs[0].poll() is None
    finally:
        flaky.stop_load(procs)
    assert procs[0].poll() is not None


def test_bad_counts_are_refused(capsys):
    import pytest
    with pytest.raises(SystemExit):
        flaky.main(["--repeat", "0", "x.test"])
    assert "--repeat must be >= 1" in capsys.readouterr().err


def test_a_demo_run_passes_on_exit_0_with_a_report_without_failed_checks(tmp_path):
    (tmp_path / "report.md").write_text("# Fleet demo\n\nall figures\n")
    assert flaky.judge_demo(0, str(tmp_path)) == (True, [])


def test_a_demo_run_fails_on_its_reports_failed_checks_its_exit_or_no_report(tmp_path):
    (tmp_path / "report.md").write_text("# Fleet demo\n\n## Checks that failed\n\n- robot_2 missing from the "
                                        "comparison\n- paths.png is empty\n")
    passed, reasons = flaky.judge_demo(1, str(tmp_path))
    assert not passed
    assert reasons == ["run_demo exited 1", "report: robot_2 missing from the comparison", "report: paths.png is empty"]
    passed, reasons = flaky.judge_demo(0, str(tmp_path / "nowhere"))
    assert not passed and reasons[0].startswith("no report: ")


def test_flaky_run_needs_a_rostest_or_demo(capsys):
    with pytest.raises(SystemExit):
        flaky.main(["--repeat", "1"])
    assert "name a rostest" in capsys.readouterr().err


def test_pytest_files_run_n_times_and_each_failure_is_named(tmp_path, capsys):
    # a real pytest run of a test file that fails on its second run only (a counter file beside it)
    test = tmp_path / "test_second_fails.py"
    test.write_text("import os\nCOUNT = os.path.join(os.path.dirname(__file__), 'count')\n\n"
                    "def test_second_run_fails():\n"
                    "    n = int(open(COUNT).read()) + 1 if os.path.exists(COUNT) else 1\n"
                    "    open(COUNT, 'w').write(str(n))\n"
                    "    assert n != 2, 'the second run broke'\n")
    out = tmp_path / "out"
    code = flaky.main(["--pytest", "--repeat", "3", "--load", "0", "--results", str(out), str(test)])
    text = capsys.readouterr().out
    assert code == 1
    assert "flaky_run: pytest %s, 3 runs" % test in text
    assert "2 of 3 passed" in text
    assert "run 2/3: FAILED" in text and "the second run broke" in text
    summary = json.loads((out / "summary.json").read_text())
    assert [r["passed"] for r in summary["runs"]] == [True, False, True]


def test_a_pytest_run_without_results_or_with_a_bad_exit_fails(tmp_path):
    assert flaky.judge_pytest(4, str(tmp_path)) == (False, ["no test results"])
    (tmp_path / "pytest.xml").write_text(PASSED_UNIT)
    assert flaky.judge_pytest(0, str(tmp_path)) == (True, [])
    assert flaky.judge_pytest(1, str(tmp_path)) == (False, ["pytest exited 1"])


def test_demo_and_pytest_exclude_each_other(capsys):
    with pytest.raises(SystemExit):
        flaky.main(["--demo", "--pytest", "x.py"])
    assert "exclude each other" in capsys.readouterr().err
