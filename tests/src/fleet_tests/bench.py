"""One run of the fleet-benefit bench (python3 -m fleet_tests.bench --robots N --out FILE), against
fleet.launch with N robots on its own master (tests/scripts/bench_fleet starts it). Robots are sent
one after another (every --interval simulated seconds, robot_0 first) to their parking spots in
the goal area, behind the blocked corridors; the run ends when every robot has finished. Goals,
corridors and blocks come from the launch's layout (/fleet/goals, else the facility's goals.yaml).
Writes FILE (JSON): stuck events, robots that drove into a blocked corridor's mouth, time to goal
per robot, distance driven, bytes published by the bridges, detection -> peer latency."""
import argparse
import json
import math
import sys

import rospy

from fleet_tests.scenario import Fleet, ScenarioError, load_facility, percentile, wait_for_sim_time


def entered_blocked(track, block, corridor, reach, depth=1.0):
    """True when the robot drove into the blocked corridor: near_block, or a track point on the start
    side of the block at least depth metres past the corridor's mouth (its start-side end, min_y:
    both layouts' corridors run up from the start hall). In the facility the blocks sit 1.7 m past
    the mouths and robots stop below them, so near_block decides; in the dead end robots drive ~7 m
    in and turn 2.4-2.6 m before the block, so the depth rule does."""
    if near_block(track, block, reach):
        return True
    by = block["pose"][1]
    x0, y0, x1, _y1 = corridor
    return any(x0 <= x <= x1 and y0 + depth <= y < by for _t, x, y in track)


def near_block(track, block, reach):
    """True when a track point on the start side (below) comes within reach (m) of the block's centre
    line: the robot drove into the corridor's mouth far enough to mark the block (obstacle_range 2.5 m)."""
    (bx, by, _yaw), (sx, _sy) = block["pose"], block["size"]
    for _t, x, y in track:
        if y >= by:
            continue
        dx = max(0.0, abs(x - bx) - sx / 2.0)
        if math.hypot(dx, y - by) <= reach:
            return True
    return False


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, required=True)
    parser.add_argument("--interval", type=float, default=20.0, help="simulated s between dispatches")
    parser.add_argument("--goal-timeout", type=float, default=400.0, help="simulated s per robot")
    parser.add_argument("--out", required=True)
    args = parser.parse_args(rospy.myargv(argv or sys.argv)[1:])
    wait_for_sim_time()
    rospy.init_node("bench_fleet_run")
    try:
        facility = load_facility(rospy.get_param("/fleet/goals", None))
    except ScenarioError as err:
        print("bench: %s" % err)
        return 2
    fleet = Fleet(args.robots, facility=facility)
    goals = fleet.facility["bench_goals"]
    if args.robots > len(goals):
        print("bench: %d robots but only %d bench_goals in %s" % (args.robots, len(goals), fleet.facility["path"]))
        return 2
    try:
        fleet.wait_ready(180.0)
    except ScenarioError as err:
        print("bench: %s" % err)
        return 1
    sent = {}
    for k, robot in enumerate(fleet.robots):
        if k:
            rospy.sleep(args.interval)
        sent[robot.name] = robot.send(goals[k])
        print("[bench N=%d] t=%.0f s: %s sent" % (args.robots, rospy.get_time(), robot.name), flush=True)
    results = {}
    for robot in fleet.robots:
        remaining = max(1.0, sent[robot.name] + args.goal_timeout - rospy.get_time())
        finished, state, text = robot.wait(remaining)
        done = rospy.get_time()
        if finished and state == "SUCCEEDED":
            results[robot.name] = done - sent[robot.name]
        print("[bench N=%d] %s: %s %s" % (args.robots, robot.name, state, text), flush=True)
    # time to goal: when the robot's result came, not when we asked; use the last track point near the goal
    times = {}
    for k, robot in enumerate(fleet.robots):
        if robot.name not in results:
            continue
        gx, gy = goals[k][0], goals[k][1]
        arrive = [t for t, x, y in robot.track if t >= sent[robot.name] and math.hypot(x - gx, y - gy) < 0.3]
        times[robot.name] = (arrive[0] if arrive else sent[robot.name] + results[robot.name]) - sent[robot.name]
    blocks = fleet.facility["blocks"]
    corridors = fleet.facility["corridors"]
    entered = sum(1 for r in fleet.robots if any(entered_blocked(r.track, b, corridors[b["corridor"]], 2.4)
                                                 for b in blocks.values()))
    lat = [x * 1000.0 for x in fleet.latencies()]
    rospy.sleep(2.5)  # one more /diagnostics round from every bridge
    bytes_pub = footprint_bytes = 0
    for r in fleet.robots:
        try:
            bytes_pub += int(float(r.bridge_stats.get("bytes_published", 0)))
            # the robots' footprint adverts (fleet robots are never shared), counted apart from obstacles
            footprint_bytes += int(float(r.bridge_stats.get("footprint_bytes_published", 0)))
        except ValueError:
            pass
    out = {
        "robots": args.robots,
        "sharing": bool(rospy.get_param("/robot_0/move_base/sharing_enabled", True)),
        "stuck": sum(len(r.stuck) for r in fleet.robots),
        "stuck_per_robot": {r.name: len(r.stuck) for r in fleet.robots},
        "entered_blocked_corridor": entered,
        "reached": len(times),
        "time_to_goal": times,
        "time_mean": sum(times.values()) / len(times) if times else float("nan"),
        "time_p95": percentile(list(times.values()), 95),
        "time_sd": (math.sqrt(sum((v - sum(times.values()) / len(times)) ** 2 for v in times.values())
                              / (len(times) - 1)) if len(times) > 1 else float("nan")),
        "time_min": min(times.values()) if times else float("nan"),
        "time_max": max(times.values()) if times else float("nan"),
        "goals_file": facility["path"],
        "distance_m": sum(r.distance for r in fleet.robots),
        "bytes_on_bus": bytes_pub,
        "footprint_bytes_on_bus": footprint_bytes,
        "shared_obstacles": sum(len(r.shares()) for r in fleet.robots),
        "latency_ms": lat,
        "latency_ms_p50": percentile(lat, 50),
        "latency_ms_p99": percentile(lat, 99),
    }
    with open(args.out, "w") as f:
        json.dump(out, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
