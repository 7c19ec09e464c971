"""One test of the demo (python3 -m fleet_tests.demo --test N --out DIR), run by scripts/run_demo.py
against a fleet.launch on its own master. Drives the steps of the thesis's Test N, takes a frame
per step (each robot's view and the world, side by side) and writes DIR/testN.json with the
steps, the sharing events and the metrics. No assertions: the rostests assert; this shows.
With --rviz PNG, RViz runs on fleet_launch's config/fleet.rviz under a virtual X server
(fleet_tests.rviz_shot) and PNG is a screenshot of it at the step named by --rviz-step; what is
wrong with the config, if anything, goes into testN.json ("rviz")."""
import argparse
import json
import math
import os
import sys
import tempfile

import rospkg
import rospy
from PIL import Image, ImageDraw

from fleet_tests.rviz_shot import RvizError, RvizSession
from fleet_tests.scenario import Fleet, ScenarioError, percentile, wait_for_sim_time

TILT = 0.2


class Demo:
    def __init__(self, test, out, rviz_png=None, rviz_step=2):
        self.test, self.out = test, out
        self.fleet = Fleet(2)
        self.steps = []
        self.goals = []
        self.rviz_png, self.rviz_step = rviz_png, rviz_step
        self.rviz = None
        self.rviz_result = None     # for testN.json: screenshot, step, config problems or the reason there is none

    def start_rviz(self):
        if not self.rviz_png:
            return
        config = os.path.join(rospkg.RosPack().get_path("fleet_launch"), "config", "fleet.rviz")
        try:
            self.rviz = RvizSession(config, tempfile.mkdtemp(prefix="demo_rviz_"), node_name="demo_rviz")
            self.rviz.start()
            self.rviz.wait_ready(120.0)
        except RvizError as err:
            self.progress("no RViz screenshot: %s" % err)
            self.rviz_result = {"error": str(err)}
            self.stop_rviz()

    def rviz_shot(self, k, caption):
        if self.rviz is None or k != self.rviz_step:
            return
        try:
            rospy.sleep(2.0)        # a few more frames of what the step left behind
            self.rviz.screenshot(self.rviz_png)
            self.rviz_result = {"png": os.path.basename(self.rviz_png), "step": k, "caption": caption,
                                "problems": self.rviz.config_problems()}
            self.progress("RViz screenshot at step %d: %s" % (k, self.rviz_png))
        except (RvizError, rospy.ROSException, OSError) as err:
            self.rviz_result = {"error": str(err)}
        self.stop_rviz()

    def stop_rviz(self):
        if self.rviz is not None:
            self.rviz.stop()
            self.rviz = None

    def progress(self, text):
        print("[demo test %d] %s" % (self.test, text), flush=True)

    def frame(self, caption):
        k = len(self.steps) + 1
        base = os.path.join(self.out, "test%d_step%02d" % (self.test, k))
        parts = []
        for r in self.fleet.robots:
            path = "%s_%s.png" % (base, r.name)
            resp = r.snapshot(path)
            if resp.success:
                parts.append((r.name + "'s view", path))
        world = base + "_world.png"
        if self.fleet.world_snapshot(world).success:
            parts.append(("world", world))
        images = [(label, Image.open(p).convert("RGB")) for label, p in parts]
        h = max(im.height for _l, im in images) + 24
        w = sum(im.width for _l, im in images) + 10 * (len(images) - 1)
        sheet = Image.new("RGB", (w, h), "white")
        draw = ImageDraw.Draw(sheet)
        x = 0
        for label, im in images:
            sheet.paste(im, (x, 24))
            draw.text((x + 4, 6), label, fill="black")
            x += im.width + 10
        sheet.save(base + ".png")
        for _l, p in parts:
            os.remove(p)
        self.steps.append({"step": k, "caption": caption, "t": rospy.get_time(), "png": os.path.basename(base + ".png")})
        self.progress("step %d: %s" % (k, caption))
        self.rviz_shot(k, caption)

    def go(self, robot, goal, timeout=300.0):
        t0 = rospy.get_time()
        finished, state, text = robot.go(goal, timeout)
        self.goals.append({"robot": robot.name, "goal": goal, "state": state, "seconds": rospy.get_time() - t0,
                           "text": text})
        return state == "SUCCEEDED"

    def run(self):
        f = self.fleet
        f.wait_ready(120.0)
        self.start_rviz()
        r0, r1 = f.robots
        self.frame("start: robot_0 (blue) and robot_1 (green) bottom right, blocks in the right and middle corridors")
        if self.test == 1:
            self.go(r1, "wait_1")
            self.frame("robot_1 waits inside the right corridor, below block_right, on robot_0's way")
            self.go(r0, "orange")
            self.frame("robot_0 reached orange; each block was shared as it appeared on robot_0's plan (magenta), "
                       "robot_1 was not")
            self.go(r1, "start_1")
            self.go(r1, "purple")
            self.frame("robot_1 planned the open left corridor from the start and reached purple")
        elif self.test == 2:
            f.remove_block("block_middle")
            self.go(r0, "orange")
            self.frame("robot_0 (middle block taken away) shared block_right and reached orange")
            self.go(r0, "purple")
            self.frame("robot_0 at purple looks down the right corridor at the block")
            f.remove_block("block_right")
            rospy.sleep(3.0)
            self.frame("block_right removed: robot_0 clears the cells and shares the update")
            self.go(r0, "orange")
            self.go(r1, "purple")
            self.frame("robot_1 drove straight through the cleared right corridor")
        else:
            duration = rospy.get_param("/robot_0/sharing_handler/obstacle_duration", 100)
            f.remove_block("block_middle")
            r0.send("orange")
            shares = f.wait_until(r0.shares, 60.0, "robot_0 to share block_right")
            rect = tuple(shares[0][1].rectangle_shape)
            uuid = shares[0][1].uuid
            self.frame("robot_0 shared block_right as it appeared on its plan")
            f.wait_until(lambda: r0.pose[0] < 8.5, 60.0, "robot_0 to leave the right corridor")
            mx, my = (rect[0] + rect[2]) / 2.0, (rect[1] + rect[3]) / 2.0
            f.remove_block("block_right")
            f.add_block("block_right", mx - 0.15 * math.sin(TILT), my + 0.15 * math.cos(TILT), TILT, 2.0, 0.3)
            self.frame("block_right put back turned by %.0f degrees; only part of its face is in the rectangle"
                       % math.degrees(TILT))
            self.go(r1, "red")
            rospy.sleep(2.0)
            self.frame("robot_1 at red monitors the obstacle: the moved face joins it where it touches it")
            self.go(r1, "start_1")
            r0.wait(100.0)
            self.frame("robot_1 back at its start, robot_0 at orange; both hold the same cells")
            f.wait_until(lambda: uuid not in r0.obstacles() and uuid not in r1.obstacles(), duration + 30.0,
                         "the obstacle to expire")
            rospy.sleep(2.5)
            self.frame("nobody saw it for obstacle_duration: the obstacle is gone from both robots, no message sent")
        self.write()

    def events(self):
        ev = []
        f = self.fleet
        with f.lock:
            for r in f.robots:
                ev += [{"t": t, "robot": r.name, "kind": "stuck"} for t, _x, _y in r.stuck]
                for t, m in r.to_fleet:
                    ev.append({"t": t, "robot": r.name, "kind": "share" if m.version == 1 else "update",
                               "uuid": m.uuid[:8], "marked": len(m.marked_indexes), "cleared": len(m.cleared_indexes)})
                ev += [{"t": t, "robot": r.name, "kind": "received", "uuid": m.uuid[:8]} for t, m in r.from_fleet]
                ev += [{"t": t, "robot": r.name, "kind": "expired", "uuid": u[:8]} for t, u in r.expired]
        return sorted(ev, key=lambda e: e["t"])

    def write(self):
        f = self.fleet
        lat = [x * 1000.0 for x in f.latencies()]
        same, lists = f.lists_identical()
        metrics = {
            "robots": {r.name: {"stuck": len(r.stuck), "shared": len(r.shares()),
                                "updates_sent": sum(1 for _t, m in r.to_fleet if m.version > 1),
                                "received": len(r.from_fleet), "distance_m": round(r.distance, 1),
                                "bytes_published": (r.bridge_stats.get("bytes_published", "0") if r.bridge_stats
                                                    else "?")}
                       for r in f.robots},
            "latency_ms_p50": percentile(lat, 50), "latency_ms_p99": percentile(lat, 99),
            "lists_identical": same, "obstacles_at_end": len(lists[0]),
        }
        with open(os.path.join(self.out, "test%d.json" % self.test), "w") as fp:
            json.dump({"test": self.test, "steps": self.steps, "goals": self.goals, "events": self.events(),
                       "metrics": metrics, "rviz": self.rviz_result}, fp, indent=1)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--test", type=int, choices=[1, 2, 3], required=True)
    parser.add_argument("--out", required=True)
    parser.add_argument("--rviz", metavar="PNG", help="run RViz (fleet.rviz, headless) and save a screenshot here")
    parser.add_argument("--rviz-step", type=int, default=2, help="the step whose frame the screenshot goes with")
    args = parser.parse_args(rospy.myargv(argv or sys.argv)[1:])
    if args.rviz_step < 1:
        parser.error("--rviz-step must be >= 1")
    os.makedirs(args.out, exist_ok=True)
    wait_for_sim_time()
    rospy.init_node("demo_test%d" % args.test)
    demo = Demo(args.test, os.path.abspath(args.out), args.rviz and os.path.abspath(args.rviz), args.rviz_step)
    try:
        demo.run()
    except (ScenarioError, rospy.ServiceException, rospy.ROSException) as err:
        print("[demo test %d] failed: %s" % (args.test, err), flush=True)
        return 1
    finally:
        demo.stop_rviz()
    return 0


if __name__ == "__main__":
    sys.exit(main())
