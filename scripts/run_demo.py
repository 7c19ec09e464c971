#!/usr/bin/python3
"""make demo: the thesis's Tests 1-3 in the simulated facility, headless and faster than real
time, each on its own ROS master (fleet.launch, two robots sharing over a private mosquitto).
Writes out/report.md with a picture per step (each robot's view beside the world with every
robot's trail), a timeline of the sharing events, the metrics table, a screenshot of RViz
(fleet_launch's config/fleet.rviz, headless under Xvfb) taken at Test 1's last step, when every
robot holds both blocks, and one VDA 5050 exchange with a master control (end of Test 1), and
prints where it is.

The run checks itself (report_checks) and exits 1, listing what failed, when: a test failed; the
demo's output has an ERROR/FATAL line or a traceback; a goal the output says was sent is not in
the metrics table; the RViz screenshot is missing, was taken before both blocks were shared or
shows no fleet-obstacle marker; a frame lacks the trails; the VDA 5050 exchange failed; or a
caption's claim is not borne out by the measured figures (CLAIMS).

Usage: scripts/run_demo.py [--speedup 3] [--tests 1 2 3] [--out out] [--no-rviz] [--no-vda] [--keep-logs]
(workspace sourced)
"""
import argparse
import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CAPTIONS = {1: "Test 1 - share and react", 2: "Test 2 - clear and share the update",
            3: "Test 3 - partial re-add and expiry"}
# A line a passing demo must not print: rospy's/roscpp's ERROR and FATAL, and Python tracebacks.
ERROR_RE = re.compile(r"\[(ERROR|FATAL)\]|^Traceback \(most recent call last\)")
SENT_RE = re.compile(r"scenario: (robot_\d+) sent to (\S+)")
# What the captions claim, as measured figures: (test, description, check(result) -> bool).
CLAIMS = [
    (1, "robot_0 shared each block once (block_middle, block_right)",
     lambda r: sorted(s["block"] or "?" for s in r["shares"] if s["robot"] == "robot_0") == ["block_middle",
                                                                                           "block_right"]),
    (1, "robot_1 shared nothing", lambda r: r["metrics"]["robots"]["robot_1"]["shared"] == 0),
    (1, "robot_1 drove through the left corridor only",
     lambda r: r["metrics"]["robots"]["robot_1"]["corridors"] == ["left"]),
    (2, "robot_0 shared block_right", lambda r: [s["block"] for s in r["shares"]] == ["block_right"]),
    (2, "robot_1 drove through the right corridor",
     lambda r: "right" in r["metrics"]["robots"]["robot_1"]["corridors"]),
    (3, "robot_0 shared block_right", lambda r: [s["block"] for s in r["shares"]] == ["block_right"]),
]
MIN_MARKER_PIXELS = 30
# The step of the first test whose frame the RViz screenshot goes with: Test 1's last, both blocks
# shared and robot_1 at purple past them. (At step 3, the first with both blocks shared, robot_1
# waits just below block_right and its laser points, drawn over the markers, hide that obstacle.)
RVIZ_STEP = {1: 4}
COLOURS = {"stuck": (220, 30, 30), "share": (200, 0, 200), "update": (40, 90, 220), "received": (30, 150, 30),
           "expired": (0, 0, 0)}


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def stop(proc):
    """SIGINT (roslaunch shuts its nodes down and mosquitto with them), then SIGKILL its group."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(30)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


def error_lines(text):
    """The lines of a captured output that a passing run must not print."""
    return [line for line in text.splitlines() if ERROR_RE.search(line)]


def run_test(test, args, out, logs, extra=()):
    """Runs one test; returns (exit code, the demo node's output, the fleet's roslaunch output). The
    node's output is printed as it comes; both are kept for report_checks."""
    port = free_port()
    env = dict(os.environ, ROS_MASTER_URI="http://127.0.0.1:%d" % port, ROS_IP="127.0.0.1",
               ROS_HOSTNAME="127.0.0.1", ROS_HOME=logs)
    duration = 100 if test == 3 else 600
    launch_log = open(os.path.join(logs, "test%d_launch.log" % test), "w")
    launch = subprocess.Popen(["roslaunch", "-p", str(port), "fleet_launch", "fleet.launch", "robots:=2",
                               "speedup:=%s" % args.speedup, "obstacle_duration:=%d" % duration],
                              stdout=launch_log, stderr=subprocess.STDOUT, env=env, start_new_session=True)
    lines = []
    try:
        node = subprocess.Popen([sys.executable, "-m", "fleet_tests.demo", "--test", str(test), "--out", out]
                                + list(extra), env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                text=True, errors="replace")

        def pump():
            for line in node.stdout:
                print(line, end="", flush=True)
                lines.append(line)
        reader = threading.Thread(target=pump, daemon=True)
        reader.start()
        try:
            rc = node.wait(args.time_limit)
        except subprocess.TimeoutExpired:
            node.kill()
            node.wait()
            print("[demo test %d] did not finish within %d s" % (test, args.time_limit), flush=True)
            rc = 1
        reader.join(10)
    finally:
        stop(launch)
        launch_log.close()
    with open(launch_log.name, errors="replace") as f:
        return rc, "".join(lines), f.read()


def timeline(results, path):
    from PIL import Image, ImageDraw
    rows = [(r["test"], robot) for r in results for robot in ("robot_0", "robot_1")]
    tmax = max([e["t"] for r in results for e in r["events"]] + [s["t"] for r in results for s in r["steps"]] + [1])
    width, left, row_h = 1100, 150, 34
    img = Image.new("RGB", (width, 40 + row_h * len(rows) + 40), "white")
    d = ImageDraw.Draw(img)
    scale = (width - left - 20) / tmax
    for k, (test, robot) in enumerate(rows):
        y = 30 + k * row_h
        d.text((6, y + 10), "Test %d %s" % (test, robot), fill="black")
        d.line((left, y + row_h // 2, width - 20, y + row_h // 2), fill=(210, 210, 210))
        res = [r for r in results if r["test"] == test][0]
        for s in res["steps"]:
            x = left + s["t"] * scale
            d.line((x, y + 4, x, y + row_h - 4), fill=(240, 170, 0))
        for e in res["events"]:
            if e["robot"] != robot:
                continue
            x = left + e["t"] * scale
            yy = y + row_h // 2 + {"stuck": -8, "share": -4, "update": 0, "received": 4, "expired": 8}[e["kind"]]
            d.ellipse((x - 3, yy - 3, x + 3, yy + 3), fill=COLOURS[e["kind"]])
    y = 40 + row_h * len(rows)
    for t in range(0, int(tmax) + 1, 20):
        x = left + t * scale
        d.line((x, 30, x, y - 10), fill=(235, 235, 235))
        d.text((x - 6, y - 6), "%d s" % t, fill="black")
    x = left
    for kind, colour in list(COLOURS.items()) + [("step (frame)", (240, 170, 0))]:
        d.ellipse((x, 10, x + 8, 18), fill=colour)
        d.text((x + 12, 8), kind, fill="black")
        x += 110
    img.save(path)


def rviz_section(results):
    """The RViz screenshot of the first test that has one, with what the config check found."""
    for r in results:
        rv = r.get("rviz")
        if not rv:
            continue
        lines = ["## RViz", ""]
        if "png" not in rv:
            return lines + ["No RViz screenshot: %s" % rv.get("error", "unknown reason"), ""]
        held = "; ".join("%s holds %s" % (robot, ", ".join(obs) or "nothing")
                         for robot, obs in sorted(rv.get("obstacles", {}).items()))
        lines += ["![rviz](%s)" % rv["png"], "",
                  "RViz (`roslaunch fleet_launch fleet.launch rviz:=true`, config `config/fleet.rviz`) during %s, "
                  "step %d: %s. Both blocks shared: %s. "
                  "The map with robot_0's global costmap faint over it (walls dark purple, inflation cyan and lilac; "
                  "robot_1's costmap is off by default), "
                  "the fleet's obstacles as the handlers' `fleet_obstacle_markers` (each obstacle's cells as cubes, "
                  "its monitored rectangle and a label: source, age, time left, cells; one colour per source, "
                  "robot_0's yellow-green: %d pixels of the picture), and in each robot's colour (robot_0 blue, "
                  "robot_1 green) its pose arrow, plan and laser scan."
                  % (CAPTIONS[r["test"]], rv["step"], rv["caption"], held, rv.get("marker_pixels", 0)), ""]
        if rv.get("problems"):
            lines += ["**RViz config problems:**", ""] + ["- " + p for p in rv["problems"]] + [""]
        else:
            lines += ["The config loaded without problems (no error or warning from rviz, every property kept).", ""]
        return lines
    return []


def vda_section(results):
    """The VDA 5050 exchange (Test 1's last step), as master control's log."""
    for r in results:
        v = r.get("vda")
        if not v:
            continue
        lines = ["## VDA 5050 exchange", ""]
        if "error" in v:
            lines += ["**The exchange failed:** %s" % v["error"], ""]
        else:
            lines += ["At the end of %s, `vda5050_bridge` ran for %s (VDA 5050 %s) on master control's own "
                      "mosquitto, and a minimal master control (`fleet_tests/vda_master.py`, paho) sent %s an "
                      "order from orange down the right corridor to its start. The state's `errors` named the "
                      "blocked edge (%s) %.2f s after the order. Master control then declared an area of the "
                      "left corridor blocked (`fleetBlockArea`, the 2.x way; 3.0 zone sets are not shown here): "
                      "%.2f s later %s's handler held it as an obstacle from `master_control` (%d cells; see the "
                      "step's frame, %s's view), and %.2f s after `fleetUnblockArea` it was gone. Wall seconds "
                      "from master control's connection:" % (
                          CAPTIONS[r["test"]], v["robot"], v["version"], v["robot"],
                          ", ".join("`%s` by obstacle %s" % (e, o[:8]) for e, o in sorted(v["blocked_edges"].items())),
                          v["state_latency_s"], v["area_latency_s"], v["robot"], v["area_cells"], v["robot"],
                          v["withdraw_latency_s"]), ""]
        lines += ["```"] + v.get("log", []) + ["```", ""]
        return lines
    return []


def measured(r):
    """What the metrics say about the test, in words (so that prose and figures cannot disagree)."""
    m = r["metrics"]["robots"]
    out = []
    for s in r.get("shares", []):
        out.append("%s shared %s at t = %.1f s, %.2f m from it (%d cells)" % (
            s["robot"], s["block"] or "an obstacle on no block", s["t"], s["distance_m"], s["cells"]))
    for robot, v in sorted(m.items()):
        out.append("%s drove through %s" % (robot, "the " + " then the ".join(v["corridors"]) + " corridor"
                                            if v["corridors"] else "no corridor"))
    stuck = sum(v["stuck"] for v in m.values())
    rec = sum(v.get("recoveries", 0) for v in m.values())
    out.append("stuck_feedback events: %d, recovery behaviours: %d" % (stuck, rec))
    return "Measured: " + "; ".join(out) + "."


def report_checks(results, outputs, args, out, launch_outputs=None):
    """What is wrong with a run, one line each ([] = the report shows what it claims). outputs:
    {test: the demo node's output}; launch_outputs: {test: the fleet's roslaunch output}."""
    problems = []
    by_test = {r["test"]: r for r in results}
    for test in args.tests:
        text = outputs.get(test, "")
        for line in error_lines(text):
            problems.append("Test %d printed: %s" % (test, line.strip()))
        for line in error_lines((launch_outputs or {}).get(test, "")):
            problems.append("Test %d, the fleet's roslaunch printed: %s" % (test, line.strip()))
        r = by_test.get(test)
        if r is None:
            problems.append("Test %d wrote no results" % test)
            continue
        sent = SENT_RE.findall(text)
        tabled = [(g["robot"], g["goal"]) for g in r["goals"]]
        if sorted(sent) != sorted(tabled):
            problems.append("Test %d: goals sent %s, in the metrics table %s" % (
                test, ", ".join("%s %s" % g for g in sent), ", ".join("%s %s" % g for g in tabled)))
        for s in r["steps"]:
            if not os.path.exists(os.path.join(out, s["png"])):
                problems.append("Test %d step %d: no picture %s" % (test, s["step"], s["png"]))
            if not s.get("trails"):
                problems.append("Test %d step %d: the frame has no trails" % (test, s["step"]))
        for claim_test, what, check in CLAIMS:
            if claim_test == test:
                try:
                    ok = check(r)
                except (KeyError, IndexError, TypeError):
                    ok = False
                if not ok:
                    problems.append("Test %d: the report claims \"%s\", the figures do not show it" % (test, what))
    first = by_test.get(args.tests[0]) if args.tests else None
    if not args.no_rviz and first is not None:
        rv = first.get("rviz") or {}
        if "png" not in rv:
            problems.append("no RViz screenshot: %s" % rv.get("error", "no step had both blocks in every robot's list"))
        else:
            if not rv.get("both_blocks_held"):
                problems.append("RViz screenshot (step %s) taken before every robot held both blocks" % rv.get("step"))
            if rv.get("marker_pixels", 0) < MIN_MARKER_PIXELS:
                problems.append("RViz screenshot shows %d fleet-obstacle marker pixels (< %d)" % (
                    rv.get("marker_pixels", 0), MIN_MARKER_PIXELS))
            if rv.get("problems"):
                problems.append("RViz config problems: %s" % "; ".join(rv["problems"]))
    if not args.no_vda and 1 in by_test:
        v = by_test[1].get("vda") or {"error": "not run"}
        if "error" in v:
            problems.append("VDA 5050 exchange: %s" % v["error"])
        elif not v.get("blocked_edges"):
            problems.append("VDA 5050 exchange: no blocked edge in the state")
    return problems


def report(results, out, elapsed, failed, problems=()):
    lines = ["# Fleet obstacle sharing - demo report", "",
             "The thesis's three tests in the facility world (fleet_launch/worlds, after Figure 5.1), two robots "
             "sharing only over MQTT (Coaty), run headless faster than real time in %.0f s of wall time. "
             "Each frame shows robot_0's view, robot_1's view (inflated costmap grey, shared obstacles magenta, "
             "footprint blue, plan green) and the simulated world (blocks red) with every robot's trail since "
             "the test's start (robot_0 dark blue, robot_1 dark green; a ring where it started, a dot where it "
             "is)." % elapsed, ""]
    if failed:
        lines += ["**Failed steps:** " + ", ".join(failed), ""]
    if problems:
        lines += ["**Checks that failed:**", ""] + ["- " + p for p in problems] + [""]
    lines += rviz_section(results)
    lines += ["## Timeline of sharing events", "", "![timeline](timeline.png)", "",
              "Simulated seconds from each test's start. Rows per test and robot: stuck events, first shares, "
              "updates sent, messages received from the fleet, local expiries; orange ticks are the frames.", ""]
    lines += ["## Metrics", "", "| test | robot | stuck_feedback | recoveries | shared | updates sent | received | "
              "corridors driven through | distance m | bytes published | latency p50 / p99 ms | goals (s) | "
              "lists identical |", "|" + "---|" * 13]
    for r in results:
        m = r["metrics"]
        for robot, v in sorted(m["robots"].items()):
            goals = ", ".join("%s %s %.0f" % (g["goal"], "ok" if g["state"] == "SUCCEEDED" else g["state"],
                                              g["seconds"]) for g in r["goals"] if g["robot"] == robot)
            lines.append("| %d | %s | %d | %d | %d | %d | %d | %s | %.1f | %s | %.1f / %.1f | %s | %s |" % (
                r["test"], robot, v["stuck"], v.get("recoveries", 0), v["shared"], v["updates_sent"], v["received"],
                ", ".join(v.get("corridors", [])) or "-", v["distance_m"],
                v["bytes_published"], m["latency_ms_p50"], m["latency_ms_p99"], goals or "-",
                "yes" if m["lists_identical"] else "NO"))
    lines.append("")
    lines.append("Latency: wall time from robot_0's layer proposing an obstacle to robot_1's layer receiving it "
                 "(handler → bridge → mosquitto → bridge → handler → layer). Goals: every goal the test sent, with "
                 "its outcome and simulated seconds from sending to the outcome. Corridors: the corridors of "
                 "goals.yaml a robot's ground-truth track entered at one end and left at the other. "
                 "stuck_feedback: messages on `stuck_feedback`; fleet.launch runs the navigation host in "
                 "move_base's default mode (`config/fleet_nav.yaml`, `stuck_feedback_on_local_failure: false`), "
                 "which publishes none, so robots do not get stuck at the blocks here: the sharing layer's "
                 "plan-blocked trigger shares a block as soon as its cells appear on the plan ahead (the distance "
                 "at which each block was shared is under each test). recoveries: move_base recovery behaviours "
                 "started (`move_base/recovery_status`). received: messages from the fleet on `from_fleet` "
                 "(in Test 1 also master control's area, from the VDA 5050 bridge).")
    lines += [""] + vda_section(results)
    for r in results:
        lines += ["", "## " + CAPTIONS[r["test"]], "", measured(r), ""]
        for s in r["steps"]:
            lines += ["**Step %d** (t = %.0f s): %s" % (s["step"], s["t"], s["caption"]), "",
                      "![step %d](%s)" % (s["step"], s["png"]), ""]
        lines += ["Events:", ""] + ["- t = %.1f s %s %s %s" % (e["t"], e["robot"], e["kind"], " ".join(
            "%s=%s" % (k, v) for k, v in e.items() if k not in ("t", "robot", "kind"))) for e in r["events"]
            if e["kind"] != "update"][:40]
    with open(os.path.join(out, "report.md"), "w") as f:
        f.write("\n".join(lines) + "\n")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--speedup", type=float, default=3.0)
    parser.add_argument("--tests", type=int, nargs="+", default=[1, 2, 3], choices=[1, 2, 3])
    parser.add_argument("--out", default=os.path.join(ROOT, "out"))
    parser.add_argument("--time-limit", type=int, default=400, help="wall seconds per test")
    parser.add_argument("--no-rviz", action="store_true", help="no RViz screenshot")
    parser.add_argument("--no-vda", action="store_true", help="no VDA 5050 exchange at the end of Test 1")
    parser.add_argument("--keep-logs", action="store_true", help="keep the ROS logs of a passing run")
    args = parser.parse_args()
    if args.speedup <= 0:
        parser.error("--speedup must be > 0, got %s" % args.speedup)
    if shutil.which("roslaunch") is None:
        print("run_demo: roslaunch not found; source the workspace (source scripts/env.sh)", file=sys.stderr)
        return 2
    out = os.path.abspath(args.out)
    os.makedirs(out, exist_ok=True)
    for old in os.listdir(out):
        if (old.startswith("test") or old in ("rviz.png", "timeline.png")) and old.endswith((".png", ".json")):
            os.remove(os.path.join(out, old))
    logs = tempfile.mkdtemp(prefix="fleet_demo_")
    start = time.time()
    results, failed, outputs, launch_outputs = [], [], {}, {}
    for k, test in enumerate(args.tests, 1):
        print("[demo %d/%d] %s (speedup %g)" % (k, len(args.tests), CAPTIONS[test], args.speedup), flush=True)
        # RViz once, in the first test, its screenshot at a step at which both blocks are shared
        extra = ["--rviz", os.path.join(out, "rviz.png")] if k == 1 and not args.no_rviz else []
        if extra and test in RVIZ_STEP:
            extra += ["--rviz-step", str(RVIZ_STEP[test])]
        if test == 1 and not args.no_vda:
            extra.append("--vda")
        rc, outputs[test], launch_outputs[test] = run_test(test, args, out, logs, extra)
        path = os.path.join(out, "test%d.json" % test)
        if rc != 0 or not os.path.exists(path):
            failed.append("Test %d (exit %d; logs in %s)" % (test, rc, logs))
        if os.path.exists(path):
            with open(path) as f:
                results.append(json.load(f))
    if results:
        timeline(results, os.path.join(out, "timeline.png"))
    problems = report_checks(results, outputs, args, out, launch_outputs)
    report(results, out, time.time() - start, failed, problems)
    print("[demo] report: %s" % os.path.join(out, "report.md"), flush=True)
    if failed or problems:
        print("[demo] failed: %s" % "; ".join(failed + problems), flush=True)
        print("[demo] logs in %s" % logs, flush=True)
        return 1
    if args.keep_logs:
        print("[demo] logs in %s" % logs, flush=True)
    else:
        shutil.rmtree(logs, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
