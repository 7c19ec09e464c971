"""One test of the demo (python3 -m fleet_tests.demo --test N --out DIR), run by scripts/run_demo.py
against a fleet.launch on its own master. Drives the steps of the thesis's Test N, takes a frame
per step (each robot's view and the world, side by side) and writes DIR/testN.json with the
steps, the sharing events and the metrics. No assertions: the rostests assert; this shows.
With --rviz PNG, RViz runs on fleet_launch's config/fleet.rviz under a virtual X server
(fleet_tests.rviz_shot) and PNG is a screenshot of it at the step named by --rviz-step (without
one: the first step at which every robot holds both blocks), with the number of fleet-obstacle
marker pixels in it and whether both blocks were held; what is wrong with the config, if anything,
goes into testN.json ("rviz").
Every frame's world picture carries each robot's trail (its ground-truth path so far). With
--vda, Test 1 ends with one VDA 5050 exchange (issue 30): vda5050_bridge for robot_0 on a
private mosquitto and a minimal master control (fleet_tests.vda_master); its log goes into
testN.json ("vda")."""
import argparse
import colorsys
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time

import rospkg
import rospy
from PIL import Image, ImageDraw

from fleet_tests.processes import stop as stop_process
from fleet_tests.rviz_shot import RvizError, RvizSession
from fleet_tests.scenario import STATE_NAMES, Fleet, ScenarioError, inside, percentile, wait_for_sim_time

TILT = 0.2
WORLD_PPM = 40.0    # pixels per metre of the world picture
# Trails on the world picture, one colour per robot (darker than the simulator's robot colours and
# their laser rays, so that they stay visible on both).
TRAIL_COLOURS = [(20, 40, 170), (0, 115, 0), (170, 60, 0), (120, 0, 140)]
# The demo's VDA 5050 step: robot_0's order from orange back to its start down the right corridor
# (through block_right), and the area master control declares blocked (inside the left corridor).
VDA_ORDER = ("orange", "purple", "red", "start_0")
VDA_AREA = [(1.3, 4.8), (2.5, 4.8), (2.5, 5.4), (1.3, 5.4)]


def draw_trails(image, trails, origin_x, origin_y, height_m, ppm, width=3):
    """Draws each robot's trail {name: [(t, x, y)]} (map frame) on a picture of the map whose
    lower-left corner is (origin_x, origin_y), height_m high, at ppm pixels per metre: a line, a
    ring at the start and a dot at the end, in TRAIL_COLOURS; returns the image."""
    draw = ImageDraw.Draw(image)

    def px(x, y):
        return (x - origin_x) * ppm, (origin_y + height_m - y) * ppm
    for k, (name, track) in enumerate(sorted(trails.items())):
        colour = TRAIL_COLOURS[k % len(TRAIL_COLOURS)]
        points = [px(x, y) for _t, x, y in track]
        if len(points) > 1:
            draw.line(points, fill=colour, width=width, joint="curve")
        if points:
            (x0, y0), (x1, y1) = points[0], points[-1]
            draw.ellipse((x0 - 6, y0 - 6, x0 + 6, y0 + 6), outline=colour, width=2)
            draw.ellipse((x1 - 4, y1 - 4, x1 + 4, y1 + 4), fill=colour)
    return image


def marker_pixels(path, colours, hue_tolerance=0.03):
    """Pixels of an RViz screenshot in one of the (r, g, b) colours (0..1) of the fleet-obstacle
    markers: same hue within hue_tolerance, saturated and bright (lighting shades the cubes)."""
    import numpy as np
    rgb = np.asarray(Image.open(path).convert("RGB"), dtype=np.float64) / 255.0
    top, low = rgb.max(axis=2), rgb.min(axis=2)
    span = np.where(top > low, top - low, 1.0)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    hue = np.where(top == r, ((g - b) / span) % 6.0,
                   np.where(top == g, (b - r) / span + 2.0, (r - g) / span + 4.0)) / 6.0
    sat = np.where(top > 0, (top - low) / np.where(top > 0, top, 1.0), 0.0)
    bright = (sat > 0.6) & (top > 0.6)
    hit = np.zeros(bright.shape, dtype=bool)
    for c in colours:
        h = colorsys.rgb_to_hsv(*c)[0]
        d = np.abs(hue - h)
        hit |= np.minimum(d, 1.0 - d) <= hue_tolerance
    return int((hit & bright).sum())


def corridors_driven(track, corridors):
    """Corridors a track drove through, in order: a stay inside the corridor's rectangle entered at
    one end (y) and left at the other. track [(t, x, y)], corridors {name: rect}."""
    out = []
    for name, rect in sorted(corridors.items(), key=lambda kv: kv[1][0]):
        before = None   # side of the last point outside: "below" / "above"
        entered_from, t_in = None, None
        for t, x, y in track:
            if inside(rect, x, y):
                if entered_from is None:
                    entered_from, t_in = before, t
                continue
            side = "below" if y < rect[1] else "above" if y > rect[3] else "side"
            if entered_from is not None:
                if entered_from in ("below", "above") and side in ("below", "above") and side != entered_from:
                    out.append((t_in, name))
                entered_from = None
            before = side
    return [name for _t, name in sorted(out)]


class Demo:
    def __init__(self, test, out, rviz_png=None, rviz_step=None, vda=False):
        self.test, self.out = test, out
        self.fleet = Fleet(2)
        self.steps = []
        self.goals = []
        self.pending = {}           # robot name -> the goal sent and not yet waited for
        self.vda, self.vda_result = vda, None
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

    def both_blocks_held(self):
        """Every robot's handler holds at least one obstacle per block of the facility."""
        blocks = len(self.fleet.facility["blocks"])
        return all(len(r.obstacles()) >= blocks for r in self.fleet.robots)

    def rviz_shot(self, k, caption):
        """The screenshot at step rviz_step, or (without one) at the first step at which both blocks
        are held by every robot; retried for a few wall seconds until the markers are drawn. Whether
        both blocks were held goes into the result ("both_blocks_held")."""
        if self.rviz is None:
            return
        if self.rviz_step is not None and k != self.rviz_step:
            return
        if self.rviz_step is None and not self.both_blocks_held():
            return
        try:
            from sharing_handler_py.markers import source_colour
            lists = [r.list_srv().obstacles for r in self.fleet.robots]
            colours = sorted({source_colour(o.source) for lst in lists for o in lst})
            end = time.time() + 15.0
            while True:
                rospy.sleep(1.0)        # a few more frames of what the step left behind
                self.rviz.screenshot(self.rviz_png)
                pixels = marker_pixels(self.rviz_png, colours) if colours else 0
                if pixels or time.time() > end:
                    break
            self.rviz_result = {"png": os.path.basename(self.rviz_png), "step": k, "caption": caption,
                                "problems": self.rviz.config_problems(), "marker_pixels": pixels,
                                "both_blocks_held": self.both_blocks_held(),
                                "obstacles": {r.name: sorted("%s from %s" % (o.uuid[:8], o.source) for o in lst)
                                              for r, lst in zip(self.fleet.robots, lists)}}
            self.progress("RViz screenshot at step %d (%d marker pixels): %s" % (k, pixels, self.rviz_png))
        except (RvizError, rospy.ROSException, rospy.ServiceException, OSError) as err:
            self.rviz_result = {"error": str(err)}
        self.stop_rviz()

    def stop_rviz(self):
        if self.rviz is not None:
            self.rviz.stop()
            shutil.rmtree(self.rviz.workdir, ignore_errors=True)     # rviz's log was read by then
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
        trails = False
        if self.fleet.world_snapshot(world, WORLD_PPM).success:
            trails = self.trails_on_world(world)
            parts.append(("world with trails" if trails else "world", world))
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
        self.steps.append({"step": k, "caption": caption, "t": rospy.get_time(), "png": os.path.basename(base + ".png"),
                           "trails": trails})
        self.progress("step %d: %s" % (k, caption))
        self.rviz_shot(k, caption)

    def trails_on_world(self, path):
        """Each robot's trail on the simulator's picture. The map frame is the facility's world frame
        (goals.yaml), and the simulator draws its grid: the world's bounds (here the floorplan, which
        the map covers) and GRID_MARGIN metres around them, at WORLD_PPM. A picture of another
        size gets no trails (the frame's "trails" is false and make demo fails)."""
        from fleet_sim.sim import GRID_MARGIN
        grid = self.fleet.map
        image = Image.open(path).convert("RGB")
        if grid is None:
            self.progress("no /map: frame without trails")
            return False
        res = grid.info.resolution
        w_m, h_m = grid.info.width * res + 2 * GRID_MARGIN, grid.info.height * res + 2 * GRID_MARGIN
        if abs(image.width - w_m * WORLD_PPM) > 2 or abs(image.height - h_m * WORLD_PPM) > 2:
            self.progress("world picture %dx%d is not the map and %.1f m around it (%.1f x %.1f m): frame "
                          "without trails" % (image.width, image.height, GRID_MARGIN, w_m, h_m))
            return False
        ox, oy = grid.info.origin.position.x - GRID_MARGIN, grid.info.origin.position.y - GRID_MARGIN
        with self.fleet.lock:
            trails = {r.name: list(r.track) for r in self.fleet.robots}
        draw_trails(image, trails, ox, oy, h_m, WORLD_PPM)
        draw = ImageDraw.Draw(image)
        x = 6
        for k, name in enumerate(sorted(trails)):
            colour = TRAIL_COLOURS[k % len(TRAIL_COLOURS)]
            draw.line((x, image.height - 10, x + 18, image.height - 10), fill=colour, width=3)
            draw.text((x + 22, image.height - 16), name + "'s trail", fill=colour)
            x += 120
        image.save(path)
        return True

    def send(self, robot, goal):
        """Sends a goal; wait() (or go()) records its outcome, write() one never waited for."""
        self.pending[robot.name] = {"robot": robot.name, "goal": goal, "t0": rospy.get_time()}
        robot.send(goal)

    def wait(self, robot, timeout=300.0):
        finished, state, text = robot.wait(timeout)
        sent = self.pending.pop(robot.name)
        self.goals.append({"robot": robot.name, "goal": sent["goal"], "state": state if finished else "NOT DONE (%s)"
                           % state, "seconds": rospy.get_time() - sent["t0"], "text": text})
        return finished and state == "SUCCEEDED"

    def go(self, robot, goal, timeout=300.0):
        self.send(robot, goal)
        return self.wait(robot, timeout)

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
            if self.vda:
                self.vda_exchange()
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
            self.send(r0, "orange")
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
            self.wait(r0, 100.0)
            self.frame("robot_1 back at its start, robot_0 at orange; both hold the same cells")
            f.wait_until(lambda: uuid not in r0.obstacles() and uuid not in r1.obstacles(), duration + 30.0,
                         "the obstacle to expire")
            rospy.sleep(2.5)
            self.frame("nobody saw it for obstacle_duration: the obstacle is gone from both robots, no message sent")
        self.write()

    def vda_exchange(self):
        """Issue 30's exchange, one robot: vda5050_bridge for robot_0 (VDA 5050 2.1.0) on a private
        mosquitto of master control; master control sends robot_0 an order down the right corridor
        and reads the blocked edge in its state, then declares an area in the left corridor
        blocked (fleetBlockArea), which robot_0's handler takes as an obstacle from
        master_control, and withdraws it (fleetUnblockArea). A frame shows the area in robot_0's
        view. Failures go into the json ("vda": {"error"}) and fail the demo."""
        from coaty_bridge.broker import Broker, BrokerError
        from fleet_tests.vda_master import MasterControl, MasterControlError, blocked_edges
        r0 = self.fleet.robots[0]
        version, manufacturer = "2.1.0", "fleet"
        broker = node = mc = None
        log_path = os.path.join(os.environ.get("ROS_HOME", tempfile.gettempdir()), "vda5050_bridge.log")
        result = {"version": version, "robot": r0.name}
        try:
            broker = Broker(allow_anonymous=True).start()
            with open(log_path, "w") as log:
                node = subprocess.Popen(["rosrun", "vda5050_bridge", "vda5050_bridge", "__ns:=" + r0.name,
                                         "__name:=vda5050_bridge", "_protocol_version:=" + version,
                                         "_manufacturer:=" + manufacturer, "_serial_number:=" + r0.name,
                                         "_broker_port:=%d" % broker.port, "_state_interval:=30.0"],
                                        stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
            prefix = "uagv/v2/%s/%s" % (manufacturer, r0.name)
            mc = MasterControl(broker.host, broker.port, prefix, version, manufacturer, r0.name)
            mc.wait_for(mc.ready.is_set, 10.0, "connection to the broker")
            mc.wait_for(mc.last_state, 60.0, "first state from robot_0's vda5050_bridge")
            nodes = [(name,) + self.fleet.goal(name)[:2] for name in VDA_ORDER]
            mc.send_order("demo-order-1", nodes)
            sent = time.time()
            edges = mc.wait_for(lambda: blocked_edges(mc.last_state()), 10.0, "blocked edge in robot_0's state")
            result["blocked_edges"] = edges
            result["state_latency_s"] = round(time.time() - sent, 3)
            mc.block_area("demo-area", VDA_AREA)
            sent = time.time()

            def area():
                return [o for o in r0.list_srv().obstacles if o.source == "master_control"]
            got = mc.wait_for(area, 10.0, "the blocked area in robot_0's obstacle list")
            result["area_latency_s"] = round(time.time() - sent, 3)
            result["area_cells"] = len(got[0].marked_indexes)
            mc.note("robot_0's handler holds obstacle %s from %s, %d cells, rectangle %s (%.2f s after the action)" % (
                got[0].uuid[:8], got[0].source, len(got[0].marked_indexes),
                ", ".join("%.2f" % v for v in got[0].rectangle_shape), result["area_latency_s"]))
            rospy.sleep(1.0)
            self.frame("VDA 5050: master control declared an area of the left corridor blocked (fleetBlockArea); "
                       "robot_0's costmap holds it (magenta, source master_control)")
            mc.unblock_area("demo-area")
            sent = time.time()
            mc.wait_for(lambda: not area(), 10.0, "the area to leave robot_0's obstacle list")
            result["withdraw_latency_s"] = round(time.time() - sent, 3)
            mc.note("the area left robot_0's obstacle list (%.2f s after the action)" % result["withdraw_latency_s"])
            time.sleep(0.3)
        except (BrokerError, MasterControlError, OSError, rospy.ServiceException, ScenarioError) as err:
            result["error"] = str(err)
            self.progress("VDA 5050 exchange failed: %s (bridge log %s)" % (err, log_path))
        finally:
            if mc is not None:
                result["log"] = mc.lines()
                mc.stop()
            stop_process(node)
            if broker is not None:
                broker.stop()
        self.vda_result = result
        if "error" not in result:
            self.progress("VDA 5050 exchange: blocked edges %s, area in %.2f s, withdrawn in %.2f s" % (
                ", ".join(sorted(result["blocked_edges"])), result["area_latency_s"], result["withdraw_latency_s"]))

    def share_facts(self):
        """Every first share: who, when, on which block, and how far the sharer was from it."""
        out = []
        blocks = self.fleet.facility["blocks"]
        for r in self.fleet.robots:
            for t, m in r.shares():
                x0, y0, x1, y1 = m.rectangle_shape
                on = [name for name, b in sorted(blocks.items())
                      if x0 - 0.3 <= float(b["pose"][0]) <= x1 + 0.3 and y0 - 0.3 <= float(b["pose"][1]) <= y1 + 0.3]
                px, py = r.pose_at(t)
                dx, dy = max(x0 - px, 0.0, px - x1), max(y0 - py, 0.0, py - y1)
                out.append({"robot": r.name, "t": t, "uuid": m.uuid[:8], "block": on[0] if on else None,
                            "distance_m": round(math.hypot(dx, dy), 2), "cells": len(m.marked_indexes)})
        return sorted(out, key=lambda e: e["t"])

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
            "robots": {r.name: {"stuck": len(r.stuck), "recoveries": len(r.recoveries), "shared": len(r.shares()),
                                "corridors": corridors_driven(r.track, f.facility["corridors"]),
                                "updates_sent": sum(1 for _t, m in r.to_fleet if m.version > 1),
                                "received": len(r.from_fleet), "distance_m": round(r.distance, 1),
                                "bytes_published": (r.bridge_stats.get("bytes_published", "0") if r.bridge_stats
                                                    else "?")}
                       for r in f.robots},
            "latency_ms_p50": percentile(lat, 50), "latency_ms_p99": percentile(lat, 99),
            "lists_identical": same, "obstacles_at_end": len(lists[0]),
        }
        for name, sent in sorted(self.pending.items()):       # sent, never waited for: in the table all the same
            robot = [r for r in f.robots if r.name == name][0]
            state = robot.client.get_state()
            self.goals.append({"robot": name, "goal": sent["goal"], "state": "NOT WAITED (%s)" % STATE_NAMES.get(
                state, state), "seconds": rospy.get_time() - sent["t0"], "text": ""})
        self.pending = {}
        with open(os.path.join(self.out, "test%d.json" % self.test), "w") as fp:
            json.dump({"test": self.test, "steps": self.steps, "goals": self.goals, "events": self.events(),
                       "shares": self.share_facts(), "metrics": metrics, "rviz": self.rviz_result,
                       "vda": self.vda_result}, fp, indent=1)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--test", type=int, choices=[1, 2, 3], required=True)
    parser.add_argument("--out", required=True)
    parser.add_argument("--rviz", metavar="PNG", help="run RViz (fleet.rviz, headless) and save a screenshot here")
    parser.add_argument("--rviz-step", type=int, help="the step whose frame the screenshot goes with (default: "
                        "the first at which every robot holds both blocks)")
    parser.add_argument("--vda", action="store_true", help="Test 1 ends with a VDA 5050 exchange (robot_0)")
    args = parser.parse_args(rospy.myargv(argv or sys.argv)[1:])
    if args.rviz_step is not None and args.rviz_step < 1:
        parser.error("--rviz-step must be >= 1")
    os.makedirs(args.out, exist_ok=True)
    wait_for_sim_time()
    rospy.init_node("demo_test%d" % args.test)
    demo = Demo(args.test, os.path.abspath(args.out), args.rviz and os.path.abspath(args.rviz), args.rviz_step,
                args.vda)
    try:
        demo.run()
    except (ScenarioError, rospy.ServiceException, rospy.ROSException) as err:
        print("[demo test %d] failed: %s" % (args.test, err), flush=True)
        return 1
    finally:
        demo.stop_rviz()
    if demo.rviz_png and demo.rviz_result is None:
        print("[demo test %d] no RViz screenshot: no step had both blocks in every robot's list" % args.test,
              flush=True)
    if demo.vda_result and "error" in demo.vda_result:
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
