#!/usr/bin/python3
"""Runs one rostest (or pytest files, or the demo) N times beside a CPU load and says how many runs passed, with each
failure's reason.

A test that passes on an idle machine but fails when the CPU is busy depends on CPU headroom (a
timeout in wall time, a controller that cannot keep up with a sped-up simulation). This runs it the
way a loaded `make test` does: ``--load K`` starts K busy processes (each a Python loop spinning at
the tests' own priority, like `yes > /dev/null`) before the first run and stops them after the
last. Each run is judged by its outcome only (rostest's exit code and its JUnit results), never by
how long it took; the reasons are the failing assertions' messages.

Usage: flaky_run.py [--repeat N] [--load K] [--results DIR] TEST...
       flaky_run.py --pytest [--repeat N] [--load K] [--results DIR] FILE...
       flaky_run.py --demo [--repeat N] [--load K] [--results DIR] [DEMO OPTION...]
  TEST is what rostest takes: a path (fleet_nav/test/nav/nav_willow.test) or PKG FILE.
  --pytest runs `python3 -m pytest FILE...` (test files that start their own master and broker, such as
  coaty_bridge/test/test_attacks_nodes.py), judged like a rostest by its exit code and its JUnit results.
  --demo runs `make demo`'s program (scripts/run_demo.py, its options after --demo's) instead, each run
  writing its report to DIR/run_<i>; a run passes when it exits 0 and its report lists no failed check.
  Prints one line per run and ends with "k of N passed"; exit 0 only when every run passed.
  Results of run i are kept in DIR/run_<i> (default test_results/flaky/<test name>/run_<i>), and
  DIR/summary.json holds the runs (outcome, reasons, exit code, load average before and after).
"""
import argparse
import glob
import json
import os
import re
import subprocess
import sys
import time
import xml.etree.ElementTree as ET

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RESULTS = os.path.join(ROOT, "test_results", "flaky")
BUSY_LOOP = "while True:\n    pass\n"


# --- judging one run (pure: files in, verdict out) ------------------------------------------------
def failure_reason(text):
    """The one line that says why a test case failed, from a JUnit <failure>/<error> text. rosunit
    writes the exception's message first and the traceback after it; unittest's "False is not
    true : " before our own message is dropped. A text that starts with the traceback gives its
    exception line."""
    text = (text or "").replace("<![CDATA[", "").replace("]]>", "")
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    if not lines:
        return "no reason given"
    line = lines[0]
    if line.startswith("Traceback") or line.startswith('File "'):
        exception = [x for x in lines if re.match(r"^[\w.]*(Error|Exception)\b", x)]
        line = re.sub(r"^[\w.]*(Error|Exception):?\s*", "", exception[-1]) if exception else lines[-1]
    # assertTrue/assertFalse put their standard message before " : " and ours after it
    m = re.match(r"^(?:False is not true|True is not false) : (.+)$", line)
    return (m.group(1) if m else line)[:400]


def read_cases(path):
    """[(name, status, reason)] of one JUnit file; status is passed, failed or skipped. A file that
    cannot be read is one failed case naming it."""
    if os.path.exists(path) and os.path.getsize(path) == 0:
        return []  # rostest leaves the test's file empty when it killed the test (its summary says why)
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as err:
        return [(os.path.basename(path), "failed", "unreadable result file %s (%s)" % (path, err))]
    cases = []
    suites = [root] if root.tag == "testsuite" else list(root.iter("testsuite"))
    for suite in suites:
        for case in suite.iter("testcase"):
            name = "%s.%s" % (case.get("classname", ""), case.get("name", ""))
            bad = case.find("failure") if case.find("failure") is not None else case.find("error")
            if bad is not None:
                cases.append((name, "failed", failure_reason(bad.get("message") or bad.text)))
            elif case.find("skipped") is not None:
                cases.append((name, "skipped", ""))
            else:
                cases.append((name, "passed", ""))
    return cases


def judge(returncode, test_cases, summary_cases, program="rostest"):
    """(passed, reasons) of one run. ``test_cases`` are the test programs' own results
    (rosunit-*.xml), ``summary_cases`` rostest's summary of them (rostest-*.xml, which also reports
    a test that never wrote results: a time limit, a required node that died). A run passes when
    rostest exited 0, some test case ran, and none failed."""
    reasons = [reason for _name, status, reason in test_cases if status == "failed"]
    if not reasons:  # the summary names failures the test itself could not write down
        reasons = [reason for _name, status, reason in summary_cases if status == "failed"]
    ran = [c for c in list(test_cases) + list(summary_cases) if c[1] != "skipped"]
    if not ran:
        reasons.append("no test results")
    if returncode != 0 and not reasons:
        reasons.append("%s exited %d" % (program, returncode))
    unique = []
    for reason in reasons:
        if reason not in unique:
            unique.append(reason)
    return not unique, unique


def judge_folder(returncode, folder):
    """judge() on the JUnit files rostest wrote under ``folder`` (its --results-base-dir)."""
    test_cases, summary_cases = [], []
    for xml in sorted(glob.glob(os.path.join(folder, "**", "*.xml"), recursive=True)):
        (summary_cases if os.path.basename(xml).startswith("rostest-") else test_cases).extend(read_cases(xml))
    return judge(returncode, test_cases, summary_cases)


def judge_pytest(returncode, folder):
    """judge() on the one JUnit file pytest wrote into ``folder`` (its --junitxml); pytest has no summary file."""
    path = os.path.join(folder, "pytest.xml")
    return judge(returncode, read_cases(path) if os.path.exists(path) else [], [], program="pytest")


def judge_demo(returncode, folder):
    """(passed, reasons) of one run of scripts/run_demo.py that wrote its report to ``folder``: it exited 0,
    its report.md exists and lists no failed check."""
    reasons = [] if returncode == 0 else ["run_demo exited %d" % returncode]
    report = os.path.join(folder, "report.md")
    try:
        with open(report) as f:
            text = f.read()
    except OSError as err:
        return False, reasons + ["no report: %s" % err]
    if "Checks that failed" in text:
        failed = text.split("Checks that failed", 1)[1].strip().splitlines()
        reasons += ["report: " + line.lstrip("- ").strip() for line in failed[:5] if line.strip().startswith("-")] \
            or ["report lists failed checks"]
    return not reasons, reasons


def summary_line(runs):
    """'k of N passed' and, after it, the loads seen (1-minute load average at the runs' starts and ends)."""
    passed = sum(1 for r in runs if r["passed"])
    loads = [r[key] for r in runs for key in ("load_before", "load_after") if r.get(key) is not None]
    text = "%d of %d passed" % (passed, len(runs))
    if loads:
        text += " (1-min load average %.1f-%.1f)" % (min(loads), max(loads))
    return text


def run_line(run, total):
    head = "run %d/%d: %s" % (run["index"], total, "passed" if run["passed"] else "FAILED")
    head += " (exit %d, %.0f s wall, load %.1f -> %.1f)" % (run["returncode"], run["wall_s"], run["load_before"],
                                                          run["load_after"])
    return head + "".join("\n    " + reason for reason in run["reasons"])


# --- running ---------------------------------------------------------------------------------------
def start_load(count):
    """``count`` busy processes at the caller's priority; stop_load() ends exactly these."""
    return [subprocess.Popen([sys.executable, "-c", BUSY_LOOP], stdin=subprocess.DEVNULL,
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL) for _ in range(count)]


def stop_load(procs):
    for proc in procs:
        if proc.poll() is None:
            proc.terminate()
    for proc in procs:
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def commit():
    """The commit under test, and whether the working tree differs from it."""
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                              check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=ROOT,
                               capture_output=True, text=True, check=True).stdout.strip()
        return head + (" (working tree modified)" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def test_name(test):
    return os.path.splitext(os.path.basename(test[-1]))[0]


def run_command(what, folder, test):
    """(command, judge) of one run writing its results to ``folder``."""
    if what == "demo":
        return [sys.executable, os.path.join(ROOT, "scripts", "run_demo.py"), "--out", folder] + test, judge_demo
    if what == "pytest":
        os.makedirs(folder, exist_ok=True)
        return ([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--junitxml",
                 os.path.join(folder, "pytest.xml")] + test, judge_pytest)
    return ["rostest", "--results-base-dir", folder] + test, judge_folder


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=10, help="runs (default 10)")
    parser.add_argument("--load", type=int, default=2, help="busy processes beside the runs (default 2; 0 = none)")
    parser.add_argument("--results", help="folder for the runs' results (default test_results/flaky/<test>)")
    parser.add_argument("--demo", action="store_true",
                        help="run scripts/run_demo.py (make demo) instead of a rostest; TEST... are its options")
    parser.add_argument("--pytest", action="store_true",
                        help="run python3 -m pytest on TEST... (test files) instead of a rostest")
    parser.add_argument("test", nargs="*", help="rostest's arguments: a .test path, or PKG FILE")
    args = parser.parse_args(argv)
    if args.repeat < 1 or args.load < 0:
        parser.error("--repeat must be >= 1 and --load >= 0")
    if args.demo and args.pytest:
        parser.error("--demo and --pytest exclude each other")
    if not args.demo and not args.test:
        parser.error("name a rostest (a .test path, or PKG FILE), test files with --pytest, or give --demo")
    what = "demo" if args.demo else "pytest" if args.pytest else "rostest"
    out = args.results or os.path.join(RESULTS, what if args.demo else test_name(args.test))
    os.makedirs(out, exist_ok=True)
    started = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    print("flaky_run: %s, %d runs beside %d busy processes, %d cores, commit %s, %s"
          % (" ".join([what] + args.test), args.repeat, args.load, os.cpu_count() or 0, commit(), started), flush=True)
    runs = []
    load = start_load(args.load)
    try:
        for i in range(1, args.repeat + 1):
            folder = os.path.join(out, "run_%d" % i)
            subprocess.run(["rm", "-rf", folder], check=False)  # a stale result must not count as this run's
            before, t0 = os.getloadavg()[0], time.monotonic()
            command, judge_run = run_command(what, folder, args.test)
            with open(folder + ".log", "w") as log:
                proc = subprocess.run(command, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT)
            passed, reasons = judge_run(proc.returncode, folder)
            run = {"index": i, "passed": passed, "reasons": reasons, "returncode": proc.returncode,
                   "wall_s": round(time.monotonic() - t0, 1), "load_before": before,
                   "load_after": os.getloadavg()[0], "log": folder + ".log"}
            runs.append(run)
            print(run_line(run, args.repeat), flush=True)
    finally:
        stop_load(load)
    with open(os.path.join(out, "summary.json"), "w") as f:
        json.dump({"test": [what] + args.test if args.demo else args.test, "load_processes": args.load,
                   "commit": commit(), "started": started, "runs": runs}, f, indent=1)
    print(summary_line(runs), flush=True)
    return 0 if all(r["passed"] for r in runs) else 1


if __name__ == "__main__":
    sys.exit(main())
