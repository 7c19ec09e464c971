#!/usr/bin/python3
"""make demo: the fleet benefit where users run it. Three robots on upstream move_base and Stage (fleet_launch's
move_base_fleet.launch: stageros, map_server, per robot move_base with the sharing layer, fake_localization,
the sharing handler and the Coaty bridge on a private mosquitto with per-robot logins) are sent one after
another from the facility's bottom hall to parking spots behind its two blocked corridors (blocks that are not
on the map); then the same dispatch again with sharing off. Writes out/report.md, which leads with the
comparison (time to goal and path per robot, on against off, who drove into a blocked corridor, when the block
was shared and when each robot knew), then the paths of both runs on the map with the shared cells, a
timeline, and the settings. Prints a progress line per step; about 5 minutes.

Why the facility: in the dead-end world upstream TrajectoryPlannerROS, with the navigation tutorials'
settings, cannot turn a robot round when its plan reverses at the block (one robot alone, sharing off, stood
15 s and aborted after its recoveries), so without sharing no robot arrives there and no time ratio exists
(launch/README, "On the real stack").

The run checks itself and exits 1, listing what failed under "Checks that failed" in the report, when: a run
gave no result; a robot is missing from the comparison; a picture is missing or empty; a figure prints as a
non-number; or a run's output has an ERROR/FATAL line or a traceback (the launch logs are kept in out/logs;
the tf-lag errors upstream base_local_planner prints on a loaded machine, and move_base giving up on a goal,
are listed in KNOWN_UPSTREAM and
counted in the report instead).

Usage: scripts/run_demo.py [--layout facility] [--robots 3] [--seed 1] [--interval 20] [--speedup 1] [--out out]
(workspace sourced: scripts/env.sh)
"""
import argparse
import glob
import importlib.machinery
import importlib.util
import json
import os
import re
import shutil
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# A line a passing demo must not print: rospy's/roscpp's ERROR and FATAL, and Python tracebacks.
ERROR_RE = re.compile(r"\[(ERROR|FATAL)\]|^Traceback \(most recent call last\)")
# ERROR lines upstream prints in a healthy run, with why they are not ours to fail on. Each is matched whole.
KNOWN_UPSTREAM = [
    # TrajectoryPlannerROS asks tf for the plan in robot_N/odom at the newest time; fake_localization's
    # map -> odom lags Stage's odometry by up to one 0.1 s step, and base_local_planner retries next cycle.
    (re.compile(r"\[ERROR\] \[[\d.]+, [\d.]+\]: Extrapolation Error: Lookup would require extrapolation [\d.]+s into "
                r"the future\.\s+Requested time [\d.]+ but the latest data is at time [\d.]+, when looking up "
                r"transform from frame \[robot_\d+/odom\] to frame \[map\]"), "base_local_planner, tf lag of one step"),
    (re.compile(r"\[ERROR\] \[[\d.]+, [\d.]+\]: Global Frame: robot_\d+/odom Plan Frame size \d+: map"),
     "base_local_planner, the second line of the same message"),
    # move_base giving up on a goal is an outcome the comparison shows (the robot is not counted as arrived, and
    # its path ends where it stopped), mostly in the run without sharing, where robots meet the blocks.
    (re.compile(r"\[ERROR\] \[[\d.]+, [\d.]+\]: Aborting because a valid control could not be found\. Even after "
                r"executing all recovery behaviors"), "move_base gave up on a goal (shown in the comparison)"),
    # rotate_recovery, one of move_base's default recovery behaviours, declines to turn a robot pressed against
    # something and says so at ERROR; move_base goes on to its next recovery. Seen in the run without sharing, where a
    # robot met block_right (the comparison counts its recoveries).
    (re.compile(r"\[ERROR\] \[[\d.]+, [\d.]+\]: Rotate recovery can't rotate in place because there is a potential "
                r"collision\. Cost: "), "move_base's rotate recovery declined to turn (a recovery the comparison counts)"),
]


def load_bench_fleet():
    loader = importlib.machinery.SourceFileLoader("bench_fleet", os.path.join(ROOT, "tests", "scripts", "bench_fleet"))
    spec = importlib.util.spec_from_loader("bench_fleet", loader)
    module = importlib.util.module_from_spec(spec)
    loader.exec_module(module)
    return module


def error_lines(text):
    """The ERROR/FATAL lines and tracebacks of a run's output, but those upstream prints in a healthy run."""
    out = []
    for line in text.splitlines():
        if ERROR_RE.search(line) and not any(p.search(line) for p, _why in KNOWN_UPSTREAM):
            out.append(line.strip()[:300])
    return out


def upstream_lines(text):
    """{why: count} of the ERROR lines upstream prints in a healthy run (KNOWN_UPSTREAM) in text."""
    counts = {}
    for line in text.splitlines():
        for pattern, why in KNOWN_UPSTREAM:
            if pattern.search(line):
                counts[why] = counts.get(why, 0) + 1
    return counts


def report_checks(rows, on, off, pictures, report_text, logs_text):
    """What makes the run a failure, each a sentence (empty: passed)."""
    failed = []
    for name, run in (("sharing on", on), ("sharing off", off)):
        if not run:
            failed.append("the run with %s gave no result" % name)
    if on and off and len(rows) != on.get("robots", len(rows)):
        failed.append("the comparison has %d robots, the runs %d" % (len(rows), on.get("robots")))
    for name, path in sorted(pictures.items()):
        if not os.path.isfile(path) or os.path.getsize(path) < 1000:
            failed.append("the %s picture %s is missing or empty" % (name, path))
    from fleet_tests.demo_report import numbers_missing
    for line in numbers_missing(report_text):
        failed.append("a figure is not a number: %s" % line[:200])
    for line in error_lines(logs_text)[:10]:
        failed.append("the run printed: %s" % line)
    if "## The paths" not in report_text or "| robot |" not in report_text:
        failed.append("the report lacks the comparison or the pictures")
    return failed


def run_console_test(out, logs):
    """[demo 3] the fleet console's browser test (fleet_console/test), which saves its screenshot of the page."""
    import subprocess
    shot = os.path.join(out, "console.png")
    if os.path.exists(shot):
        os.remove(shot)
    print("[demo 3] the fleet console in headless Chromium against a running fleet ...", flush=True)
    with open(os.path.join(logs, "console_test.log"), "w") as log:
        proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                               os.path.join(ROOT, "fleet_console", "test", "test_console_browser.py")],
                              stdout=log, stderr=subprocess.STDOUT, env=dict(os.environ, FLEET_CONSOLE_SHOT=shot))
    outcome = ("passed" if os.path.exists(shot) else "skipped, no screenshot (see out/logs/console_test.log)") \
        if proc.returncode == 0 else "FAILED (exit %d; out/logs/console_test.log)" % proc.returncode
    print("[demo 3] fleet console test %s" % outcome, flush=True)
    return outcome


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--layout", default="facility", choices=("facility", "deadend", "corridors"))
    parser.add_argument("--robots", type=int, default=3)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--interval", type=float, default=20.0, help="mean simulated s between two dispatches")
    parser.add_argument("--speedup", type=float, default=1.0, help="Stage's simulated s per wall s")
    parser.add_argument("--out", default=os.path.join(ROOT, "out"))
    args = parser.parse_args(argv)
    if not 1 <= args.robots <= 10 or not args.speedup > 0 or args.interval < 0:
        parser.error("--robots must be 1..10, --speedup > 0, --interval >= 0")
    from fleet_tests import demo_report
    from fleet_tests.scenario import load_facility
    from fleet_sim.map_io import load_map_yaml
    import rospkg

    bench = load_bench_fleet()
    out = os.path.abspath(args.out)
    logs = os.path.join(out, "logs")
    shutil.rmtree(logs, ignore_errors=True)
    os.makedirs(logs)
    bench_args = bench.make_parser().parse_args(
        ["--host", "stage", "--layout", args.layout, "--robots", str(args.robots), "--seed", str(args.seed),
         "--interval", str(args.interval), "--speedup", str(args.speedup)])
    worlds = os.path.join(rospkg.RosPack().get_path("fleet_launch"), "worlds")
    facility = load_facility(os.path.join(worlds, "goals.yaml" if args.layout == "facility"
                                          else args.layout + "_goals.yaml"))
    results = {}
    for step, sharing in enumerate((True, False), 1):
        started = time.time()
        print("[demo %d/2] %d robots, %s world, sharing %s: upstream move_base on Stage (real time x %g)..."
              % (step, args.robots, args.layout, "on" if sharing else "off", args.speedup), flush=True)
        results[sharing] = bench.run(args.robots, sharing, args.seed, bench_args, logs)
        r = results[sharing]
        print("[demo %d/2] %s in %.0f s wall" % (
            step, "no result" if r is None else "%d/%d robots reached their goals, mean time to goal %.1f s"
            % (r["reached"], args.robots, r["time_mean"]), time.time() - started), flush=True)
    console_png, console_outcome = os.path.join(out, "console.png"), run_console_test(out, logs)
    on, off = results[True], results[False]
    blocked = sorted({b["corridor"] for b in facility["blocks"].values()})
    pictures = {"paths": os.path.join(out, "paths.png"), "timeline": os.path.join(out, "timeline.png")}
    for path in pictures.values():
        if os.path.exists(path):
            os.remove(path)
    rows, failed_early = [], []
    try:
        rows = demo_report.compare(on, off, blocked)
    except demo_report.ReportError as err:
        failed_early.append(str(err))
    report_text = ""
    if rows:
        grid = load_map_yaml(os.path.join(worlds, args.layout + ".yaml"))
        blocks = [dict(b, pose=list(b["pose"])) for b in facility["blocks"].values()]
        demo_report.draw_paths(pictures["paths"], grid, blocks, on, off)
        spans = {}
        for corridor in blocked:
            for key, found in list(demo_report.blocked_spans(on, facility["corridors"][corridor]).items()) + \
                    list(demo_report.blocked_spans(off, facility["corridors"][corridor]).items()):
                spans[key] = sorted(spans.get(key, []) + found)
        demo_report.draw_timeline(pictures["timeline"], rows, on, off, spans)
        report_text = demo_report.markdown(rows, on, off, bench.stage_non_defaults(bench_args),
                                           {k: os.path.basename(v) for k, v in pictures.items()}, blocked)
    logs_text = ""
    for path in sorted(glob.glob(os.path.join(logs, "*_launch.log"))):
        with open(path, errors="replace") as f:
            logs_text += f.read()
    known = upstream_lines(logs_text)
    if report_text:
        report_text += "- ERROR lines upstream printed in the launch logs (not failures: see scripts/run_demo.py " \
                       "KNOWN_UPSTREAM): %s\n" % ("; ".join("%d x %s" % (n, why) for why, n in sorted(known.items()))
                                                  or "none")
    if report_text:
        report_text += demo_report.console_section(
            os.path.basename(console_png) if os.path.exists(console_png) else "", console_outcome)
    failed = failed_early + report_checks(rows, on, off, pictures, report_text, logs_text)
    if failed:
        report_text += "\n## Checks that failed\n\n" + "\n".join("- " + f for f in failed) + "\n"
    with open(os.path.join(out, "report.md"), "w") as f:
        f.write(report_text or "# Fleet demo\n")
    with open(os.path.join(out, "results.json"), "w") as f:
        json.dump({"on": on, "off": off}, f)
    print("demo: report in %s (pictures %s; launch logs in %s)" % (
        os.path.join(out, "report.md"), ", ".join(os.path.basename(p) for p in pictures.values()), logs), flush=True)
    for f in failed:
        print("demo: CHECK FAILED: %s" % f, flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
