#!/usr/bin/python3
"""make demo: the thesis's Tests 1-3 in the simulated facility, headless and faster than real
time, each on its own ROS master (fleet.launch, two robots sharing over a private mosquitto).
Writes out/report.md with a picture per step (each robot's view beside the world), a timeline of
the sharing events, the metrics table and a screenshot of RViz (fleet_launch's config/fleet.rviz,
headless under Xvfb) taken during the first test, and prints where it is.

Usage: scripts/run_demo.py [--speedup 3] [--tests 1 2 3] [--out out] [--no-rviz]   (workspace sourced)
"""
import argparse
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CAPTIONS = {1: "Test 1 - share and react", 2: "Test 2 - clear and share the update",
            3: "Test 3 - partial re-add and expiry"}
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


def run_test(test, args, out, logs, extra=()):
    port = free_port()
    env = dict(os.environ, ROS_MASTER_URI="http://127.0.0.1:%d" % port, ROS_IP="127.0.0.1",
               ROS_HOSTNAME="127.0.0.1", ROS_HOME=logs)
    duration = 100 if test == 3 else 600
    launch_log = open(os.path.join(logs, "test%d_launch.log" % test), "w")
    launch = subprocess.Popen(["roslaunch", "-p", str(port), "fleet_launch", "fleet.launch", "robots:=2",
                               "speedup:=%s" % args.speedup, "obstacle_duration:=%d" % duration],
                              stdout=launch_log, stderr=subprocess.STDOUT, env=env, start_new_session=True)
    try:
        node = subprocess.run([sys.executable, "-m", "fleet_tests.demo", "--test", str(test), "--out", out]
                              + list(extra), env=env, timeout=args.time_limit)
        return node.returncode
    except subprocess.TimeoutExpired:
        print("[demo test %d] did not finish within %d s" % (test, args.time_limit), flush=True)
        return 1
    finally:
        stop(launch)
        launch_log.close()


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
        lines += ["![rviz](%s)" % rv["png"], "",
                  "RViz (`roslaunch fleet_launch fleet.launch rviz:=true`, config `config/fleet.rviz`) during %s, "
                  "step %d: %s. The map (walls black), robot_0's global costmap faint over it (robot_1's is off by "
                  "default), shared obstacles as magenta markers, and in each robot's colour (robot_0 blue, "
                  "robot_1 green) its pose arrow, plan and laser scan."
                  % (CAPTIONS[r["test"]], rv["step"], rv["caption"]), ""]
        if rv.get("problems"):
            lines += ["**RViz config problems:**", ""] + ["- " + p for p in rv["problems"]] + [""]
        else:
            lines += ["The config loaded without problems (no error or warning from rviz, every property kept).", ""]
        return lines
    return []


def report(results, out, elapsed, failed):
    lines = ["# Fleet obstacle sharing - demo report", "",
             "The thesis's three tests in the facility world (fleet_launch/worlds, after Figure 5.1), two robots "
             "sharing only over MQTT (Coaty), run headless faster than real time in %.0f s of wall time. "
             "Each frame shows robot_0's view, robot_1's view (inflated costmap grey, shared obstacles magenta, "
             "footprint blue, plan green) and the simulated world (blocks red)." % elapsed, ""]
    if failed:
        lines += ["**Failed steps:** " + ", ".join(failed), ""]
    lines += rviz_section(results)
    lines += ["## Timeline of sharing events", "", "![timeline](timeline.png)", "",
              "Simulated seconds from each test's start. Rows per test and robot: stuck events, first shares, "
              "updates sent, messages received from the fleet, local expiries; orange ticks are the frames.", ""]
    lines += ["## Metrics", "", "| test | robot | stuck | shared | updates sent | received | distance m | "
              "bytes published | latency p50 / p99 ms | goals (s) | lists identical |", "|" + "---|" * 11]
    for r in results:
        m = r["metrics"]
        for robot, v in sorted(m["robots"].items()):
            goals = ", ".join("%s %s %.0f" % (g["goal"], "ok" if g["state"] == "SUCCEEDED" else g["state"],
                                              g["seconds"]) for g in r["goals"] if g["robot"] == robot)
            lines.append("| %d | %s | %d | %d | %d | %d | %.1f | %s | %.1f / %.1f | %s | %s |" % (
                r["test"], robot, v["stuck"], v["shared"], v["updates_sent"], v["received"], v["distance_m"],
                v["bytes_published"], m["latency_ms_p50"], m["latency_ms_p99"], goals or "-",
                "yes" if m["lists_identical"] else "NO"))
    lines.append("")
    lines.append("Latency: wall time from robot_0's layer proposing an obstacle to robot_1's layer receiving it "
                 "(handler → bridge → mosquitto → bridge → handler → layer).")
    for r in results:
        lines += ["", "## " + CAPTIONS[r["test"]], ""]
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
    args = parser.parse_args()
    if args.speedup <= 0:
        parser.error("--speedup must be > 0, got %s" % args.speedup)
    if shutil.which("roslaunch") is None:
        print("run_demo: roslaunch not found; source the workspace (source scripts/env.sh)", file=sys.stderr)
        return 2
    out = os.path.abspath(args.out)
    os.makedirs(out, exist_ok=True)
    for old in os.listdir(out):
        if (old.startswith("test") or old == "rviz.png") and old.endswith((".png", ".json")):
            os.remove(os.path.join(out, old))
    logs = tempfile.mkdtemp(prefix="fleet_demo_")
    start = time.time()
    results, failed = [], []
    for k, test in enumerate(args.tests, 1):
        print("[demo %d/%d] %s (speedup %g)" % (k, len(args.tests), CAPTIONS[test], args.speedup), flush=True)
        # RViz once, in the first test, its screenshot at step 2 (Test 1: both blocks shared)
        extra = ["--rviz", os.path.join(out, "rviz.png")] if k == 1 and not args.no_rviz else []
        rc = run_test(test, args, out, logs, extra)
        path = os.path.join(out, "test%d.json" % test)
        if rc != 0 or not os.path.exists(path):
            failed.append("Test %d (exit %d; logs in %s)" % (test, rc, logs))
        if os.path.exists(path):
            with open(path) as f:
                results.append(json.load(f))
    if results:
        timeline(results, os.path.join(out, "timeline.png"))
    report(results, out, time.time() - start, failed)
    print("[demo] report: %s" % os.path.join(out, "report.md"), flush=True)
    if failed:
        print("[demo] failed: %s" % "; ".join(failed), flush=True)
        return 1
    shutil.rmtree(logs, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
