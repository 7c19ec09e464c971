"""One run of the fleet-benefit bench (python3 -m fleet_tests.bench --robots N --seed S --out FILE),
against fleet.launch with N robots on its own master (tests/scripts/bench_fleet starts it).

Dispatch: random.Random(seed) shuffles the order in which the robots are sent and draws each
interval between two dispatches uniformly from 0.5..1.5 x --interval (simulated s); the k-th
robot sent parks at bench_goals[k] (farthest first, so no robot passes a parked one). The same
seed gives the same dispatch with sharing on and off (a paired comparison). The run ends when
every robot has finished. Goals, corridors and blocks come from the launch's layout
(/fleet/goals, else the facility's goals.yaml).

Writes FILE (JSON): the dispatch, stuck_feedback events and recovery events
(move_base/recovery_status messages), robots that crossed the mouth line of a blocked corridor,
time to goal per robot, distance driven, bytes through the broker ($SYS counters, with fan-out and
MQTT overhead) and the bridges' payload bytes, detection -> peer latency, and the obstacles shared
(distinct after merging) with how many were robots and how many were walls."""
import argparse
import json
import math
import random
import sys
import time

from fleet_tests.ground_truth import run_figures
from fleet_tests.broker_counters import sys_message_bytes  # noqa: F401 (metrics, tests)
from fleet_tests.scenario import percentile  # noqa: F401 (metrics, tests)


# ---------------------------------------------------------------------------------------------
# Metrics (pure functions, tests/test/test_bench_metrics.py)

def dispatch_plan(robots, seed, interval):
    """[(robot index, simulated s to wait before sending it)], in dispatch order: the order is a
    shuffle of 0..robots-1 and every wait but the first is uniform in 0.5..1.5 x interval, both
    from random.Random(seed) alone, so sharing on and off get the same dispatch."""
    rng = random.Random(seed)
    order = list(range(robots))
    rng.shuffle(order)
    return [(index, 0.0 if k == 0 else rng.uniform(0.5, 1.5) * interval) for k, index in enumerate(order)]


def crossed_mouth(track, corridor):
    """True when the track crossed the corridor's mouth line: its start-side end, the segment
    y = min_y, min_x <= x <= max_x (both layouts' corridors run up from the start hall), going
    in (from y < min_y to y >= min_y), with x on the line where the step crosses it. Coming
    close to the block without crossing that line (as robots in the facility do: they see the
    block from below the mouth) is not entering."""
    x0, y0, x1, _y1 = corridor
    for (_ta, xa, ya), (_tb, xb, yb) in zip(track, track[1:]):
        if ya < y0 <= yb:
            x = xa + (xb - xa) * (y0 - ya) / (yb - ya)
            if x0 <= x <= x1:
                return True
    return False


def near_block(track, block, reach):
    """True when a track point on the start side (below) comes within reach (m) of the block's
    centre line (the earlier bench's "into a blocked corridor"; kept in the JSON only)."""
    (bx, by, _yaw), (sx, _sy) = block["pose"], block["size"]
    for _t, x, y in track:
        if y >= by:
            continue
        dx = max(0.0, abs(x - bx) - sx / 2.0)
        if math.hypot(dx, y - by) <= reach:
            return True
    return False


def pose_at(track, t):
    """(x, y) of a (t, x, y) track at time t, interpolated; None outside the track."""
    if not track or t < track[0][0] or t > track[-1][0]:
        return None
    lo, hi = 0, len(track) - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if track[mid][0] <= t:
            lo = mid
        else:
            hi = mid
    (ta, xa, ya), (tb, xb, yb) = track[lo], track[hi]
    if tb <= ta:
        return xa, ya
    f = (t - ta) / (tb - ta)
    return xa + f * (xb - xa), ya + f * (yb - ya)


def rect_gap(a, b):
    """Gap between rectangles [min_x, min_y, max_x, max_y] along the axis where they lie farthest
    apart (0 when they overlap or touch): the sharing handler's merge distance."""
    return max(0.0, b[0] - a[2], a[0] - b[2], b[1] - a[3], a[1] - b[3])


def obstacle_groups(messages, merge_distance, lifetime):
    """The obstacles shared, distinct after merging: a list of sorted uuid lists. messages are
    (sim time, uuid, rectangle) of every to_fleet message of every robot. Two uuids are one
    obstacle when the handlers would have merged them: their rectangles (the union of each uuid's
    rectangles) lie within merge_distance and both were alive at once (a uuid lives from its first
    message to lifetime s after its last)."""
    info = {}
    for t, uuid, rect in messages:
        if not uuid:
            continue
        first, last, r = info.get(uuid, (t, t, tuple(rect)))
        r = (min(r[0], rect[0]), min(r[1], rect[1]), max(r[2], rect[2]), max(r[3], rect[3]))
        info[uuid] = (min(first, t), max(last, t), r)
    parent = {u: u for u in info}

    def find(u):
        while parent[u] != u:
            parent[u] = parent[parent[u]]
            u = parent[u]
        return u

    uuids = sorted(info)
    for i, a in enumerate(uuids):
        for b in uuids[i + 1:]:
            (fa, la, ra), (fb, lb, rb) = info[a], info[b]
            if fa <= lb + lifetime and fb <= la + lifetime and rect_gap(ra, rb) <= merge_distance:
                parent[find(b)] = find(a)
    groups = {}
    for u in uuids:
        groups.setdefault(find(u), []).append(u)
    return sorted(groups.values())


class OccupancyIndex:
    """Occupied cells of an a-priori map (nav_msgs/OccupancyGrid fields), for distance queries."""

    def __init__(self, width, height, resolution, origin_x, origin_y, data, occupied=65):
        self.w, self.h, self.res = width, height, resolution
        self.ox, self.oy = origin_x, origin_y
        self.occ = [v >= occupied for v in data]

    @classmethod
    def from_msg(cls, msg):
        return cls(msg.info.width, msg.info.height, msg.info.resolution, msg.info.origin.position.x,
                   msg.info.origin.position.y, msg.data)

    def near(self, x, y, dist):
        """True when (x, y) lies within dist (m) of an occupied cell (distance to the cell's square)."""
        reach = int(math.ceil(dist / self.res)) + 1
        cx, cy = int(math.floor((x - self.ox) / self.res)), int(math.floor((y - self.oy) / self.res))
        for iy in range(max(0, cy - reach), min(self.h, cy + reach + 1)):
            for ix in range(max(0, cx - reach), min(self.w, cx + reach + 1)):
                if not self.occ[iy * self.w + ix]:
                    continue
                x0, y0 = self.ox + ix * self.res, self.oy + iy * self.res
                dx = max(0.0, x0 - x, x - (x0 + self.res))
                dy = max(0.0, y0 - y, y - (y0 + self.res))
                if math.hypot(dx, dy) <= dist:
                    return True
        return False


def block_rect(block, margin=0.0):
    """[min_x, min_y, max_x, max_y] of an axis-aligned block of a goals file, grown by margin."""
    (bx, by, _yaw), (sx, sy) = block["pose"], block["size"]
    return (bx - sx / 2 - margin, by - sy / 2 - margin, bx + sx / 2 + margin, by + sy / 2 + margin)


def classify_obstacles(groups, cells, tracks, robot_radius, walls, blocks=(), margin=0.1, evidence=None):
    """{uuid group index: (was a robot, was a wall)} for the groups of obstacle_groups.

    cells: [(sim time, source robot, uuid, [(x, y) of each marked cell])] of every to_fleet message.
    A group was a robot when a marked cell of any of its messages lies within robot_radius + margin
    of another robot's (not the message's source) ground-truth pose (tracks: name -> [(t, x, y)])
    at the message's time. It was a wall when a marked cell lies within margin of an occupied cell
    of the a-priori map (walls: OccupancyIndex) and not within margin of a simulator block
    (blocks: rectangles from the goals file): the blocks reach 0.1 m into the corridor walls, so the
    cells of every block face touch a wall; only cells the blocks do not explain count.
    evidence (a dict, optional) gets, per group found to be a robot or a wall, the first cell that
    showed it: {k: {"robot": [t, x, y, robot name, distance m], "wall": [t, x, y]}}."""
    of_uuid = {u: k for k, group in enumerate(groups) for u in group}
    out = {k: [False, False] for k in range(len(groups))}
    for t, source, uuid, points in cells:
        k = of_uuid.get(uuid)
        if k is None:
            continue
        others = [(name, pose_at(track, t)) for name, track in tracks.items() if name != source]
        others = [(name, p) for name, p in others if p is not None]
        for x, y in points:
            if not out[k][0]:
                for name, (px, py) in others:
                    d = math.hypot(x - px, y - py)
                    if d <= robot_radius + margin:
                        out[k][0] = True
                        if evidence is not None:
                            evidence.setdefault(k, {})["robot"] = [t, x, y, name, round(d, 3)]
                        break
            if (not out[k][1] and walls is not None and walls.near(x, y, margin)
                    and not any(r[0] - margin <= x <= r[2] + margin and r[1] - margin <= y <= r[3] + margin
                                for r in blocks)):
                out[k][1] = True
                if evidence is not None:
                    evidence.setdefault(k, {})["wall"] = [t, x, y]
    return {k: tuple(v) for k, v in out.items()}


def broker_bytes(base, end, robots, own_bytes=0):
    """Bytes through the broker between two $SYS publications, base and end:
    {"sent", "received", "total", "sim_minutes", "per_robot_per_minute"}. base and end are
    (bytes sent, bytes received, simulated s when the publication arrived); sent counts the
    broker's fan-out to every subscriber, received what the clients sent it, both with MQTT framing,
    CONNECT/SUBSCRIBE/PING and Coaty Discover/Resolve; own_bytes (the $SYS messages the bench's
    own subscription received in between) is taken off the sent side."""
    sent = end[0] - base[0] - own_bytes
    received = end[1] - base[1]
    if sent < 0 or received < 0:
        raise ValueError("$SYS counters went backwards (%r -> %r): broker restarted?" % (base, end))
    minutes = (end[2] - base[2]) / 60.0
    total = sent + received
    per = total / robots / minutes if robots > 0 and minutes > 0 else float("nan")
    return {"sent": sent, "received": received, "total": total, "sim_minutes": minutes,
            "per_robot_per_minute": per}


# ---------------------------------------------------------------------------------------------
# The run

def thin(track, period):
    """The points of a track [(t, x, y)] at least `period` s apart (the first and the last kept)."""
    out = []
    for point in track:
        if not out or point[0] - out[-1][0] >= period:
            out.append(point)
    if track and out[-1] is not track[-1]:
        out.append(track[-1])
    return out


def knew_block(fleet, blocks):
    """{robot: sim time} at which each robot first knew of a block: the first shared obstacle with a cell on one
    that its layer got (from its handler: its own share or a peer's), or None."""
    from fleet_tests.ground_truth import on_block
    from fleet_tests.scenario import cell_centre
    out = {}
    for robot in fleet.robots:
        with fleet.lock:
            got = list(robot.layer_in)
        times = [t for t, m in got if m.marked_indexes and any(
            on_block(*cell_centre(m, i), m.resolution, b) for i in m.marked_indexes for b in blocks.values())]
        out[robot.name] = round(min(times), 2) if times else None
    return out


def robot_radius_param():
    """Circumscribed radius of robot_0's padded footprint (the navigation tutorials'), else its
    robot_radius: the "footprint radius" of the robot test."""
    import rospy
    from fleet_nav.params import NavParams
    tree = rospy.get_param("/robot_0/move_base", {})
    params, _unused = NavParams.from_dict(tree, "robot_0")
    return params.robot_extent


def main(argv=None):
    import rospy
    from fleet_tests.broker_counters import BrokerCounters
    from fleet_tests.scenario import Fleet, ScenarioError, cell_centre, fleet_sharing, load_facility, wait_for_sim_time

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, required=True)
    parser.add_argument("--seed", type=int, default=0, help="drives the dispatch order and intervals")
    parser.add_argument("--interval", type=float, default=20.0, help="mean simulated s between dispatches")
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
    sharing = fleet_sharing()
    counters, base = None, None
    if sharing:
        try:
            counters = BrokerCounters(rospy.get_param("/fleet/broker_url"), rospy.get_param("/fleet/broker_monitor", None))
            base = counters.next_sample(time.time())
        except (KeyError, OSError, ScenarioError) as err:
            print("bench: broker byte counters: %s" % err)
            return 1
    plan = dispatch_plan(args.robots, args.seed, args.interval)
    started_sim, started_wall = rospy.get_time(), time.time()
    sent, dispatch, goal_of = {}, [], {}
    for k, (index, wait) in enumerate(plan):
        robot = fleet.robots[index]
        if wait:
            rospy.sleep(wait)
        goal_of[robot.name] = goals[k]
        sent[robot.name] = robot.send(goals[k])
        dispatch.append({"robot": robot.name, "goal": list(goals[k]), "wait_s": round(wait, 3), "sent_at": sent[robot.name]})
        print("[bench N=%d seed %d] t=%.0f s: %s sent to bench_goals[%d]" % (args.robots, args.seed, rospy.get_time(),
                                                                         robot.name, k), flush=True)
    results = {}
    for index, _wait in plan:
        robot = fleet.robots[index]
        remaining = max(1.0, sent[robot.name] + args.goal_timeout - rospy.get_time())
        finished, state, text = robot.wait(remaining)
        done = rospy.get_time()
        if finished and state == "SUCCEEDED":
            results[robot.name] = done - sent[robot.name]
        print("[bench N=%d seed %d] %s: %s %s" % (args.robots, args.seed, robot.name, state, text), flush=True)
    ended_sim, ended_wall = rospy.get_time(), time.time()
    # time to goal: the first track point near the goal after dispatch, else when the result came
    times = {}
    for robot in fleet.robots:
        if robot.name not in results:
            continue
        gx, gy = goal_of[robot.name][0], goal_of[robot.name][1]
        arrive = [t for t, x, y in robot.track if t >= sent[robot.name] and math.hypot(x - gx, y - gy) < 0.3]
        times[robot.name] = (arrive[0] if arrive else sent[robot.name] + results[robot.name]) - sent[robot.name]
    blocks = fleet.facility["blocks"]
    corridors = fleet.facility["corridors"]
    blocked = sorted({b["corridor"] for b in blocks.values()})
    with fleet.lock:
        tracks = {r.name: list(r.track) for r in fleet.robots}
        to_fleet = [(r.name, t, m) for r in fleet.robots for t, m in r.to_fleet]
        grid = fleet.map
    entered = {name: [c for c in blocked if crossed_mouth(track, corridors[c])] for name, track in tracks.items()}
    near = sum(1 for track in tracks.values() if any(near_block(track, b, 2.4) for b in blocks.values()))
    lat = [x * 1000.0 for x in fleet.latencies()]
    missed = fleet.latency_pairs_missed
    rospy.sleep(2.5)  # one more /diagnostics round from every bridge
    payload = footprint_bytes = 0
    for r in fleet.robots:
        try:
            payload += int(float(r.bridge_stats.get("bytes_published", 0)))
            # the robots' footprint adverts (fleet robots are never shared), counted apart from obstacles
            footprint_bytes += int(float(r.bridge_stats.get("footprint_bytes_published", 0)))
        except ValueError:
            pass
    broker = None
    if counters is not None:
        try:
            end = counters.next_sample(time.time())
            broker = broker_bytes(base[2:4] + (base[1],), end[2:4] + (end[1],), args.robots,
                                  counters.own_bytes(base[0], end[0]))
        except (ScenarioError, ValueError) as err:
            print("bench: broker byte counters: %s" % err)
        counters.close()
    # obstacles shared, distinct after merging, and which of them were robots or walls
    lifetime = float(rospy.get_param("/robot_0/sharing_handler/obstacle_duration", 1200.0))
    merge_distance = float(rospy.get_param("/robot_0/sharing_handler/merge_distance", 0.5))
    groups = obstacle_groups([(t, m.uuid, tuple(m.rectangle_shape)) for _n, t, m in to_fleet],
                             merge_distance, lifetime)
    cells = [(t, m.source or name, m.uuid, [cell_centre(m, i) for i in m.marked_indexes]) for name, t, m in to_fleet]
    walls = OccupancyIndex.from_msg(grid) if grid is not None else None
    radius = robot_radius_param()
    evidence = {}
    kinds = classify_obstacles(groups, cells, tracks, radius, walls, [block_rect(b) for b in blocks.values()],
                               evidence=evidence)
    recoveries = {r.name: [name for _t, _x, _y, name in r.recoveries] for r in fleet.robots}
    tolerance = int(rospy.get_param("/robot_0/move_base/global_costmap/sharing_layer/static_tolerance", 3))
    truth = run_figures([(t, m.source, m.resolution, [cell_centre(m, i) for i in m.marked_indexes])
                         for name, t, m in to_fleet if m.source == name and m.marked_indexes],
                        tracks, blocks, corridors, (tolerance + 1) * (grid.info.resolution if grid else 0.05), walls)
    out = {
        "robots": args.robots,
        "realtime_factor": (ended_sim - started_sim) / max(1e-6, ended_wall - started_wall),
        "sim_s": ended_sim - started_sim,
        "wall_s": ended_wall - started_wall,
        "simulator": fleet.simulator,
        "tracks": {name: [[round(t, 2), round(x, 3), round(y, 3)] for t, x, y in thin(track, 0.5)]
                   for name, track in tracks.items()},
        "shares": [{"t": round(t, 2), "robot": name, "uuid": m.uuid, "version": m.version,
                    "cells": [[round(x, 3), round(y, 3)] for x, y in (cell_centre(m, i) for i in m.marked_indexes)]}
                   for name, t, m in to_fleet if m.source == name and m.marked_indexes],
        "knew_block": knew_block(fleet, blocks),
        "seed": args.seed,
        "sharing": sharing,
        "dispatch": dispatch,
        "stuck": sum(len(r.stuck) for r in fleet.robots),
        "stuck_per_robot": {r.name: len(r.stuck) for r in fleet.robots},
        "recoveries": sum(len(v) for v in recoveries.values()),
        "recoveries_per_robot": recoveries,
        "entered_blocked_corridor": sum(1 for v in entered.values() if v),
        "entered_per_robot": entered,
        "near_block_2_4m": near,
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
        "payload_bytes_bridges": payload,
        "footprint_bytes_bridges": footprint_bytes,
        "broker_bytes": broker,
        "broker_bytes_per_robot_per_min": broker["per_robot_per_minute"] if broker else (0.0 if not sharing else float("nan")),
        "shared_first": sum(len(r.shares()) for r in fleet.robots),
        "obstacles": len(groups),
        "obstacle_groups": groups,
        "obstacles_robots": sum(1 for robot, _wall in kinds.values() if robot),
        "obstacles_walls": sum(1 for _robot, wall in kinds.values() if wall),
        "obstacle_kinds": {",".join(groups[k]): dict({"robot": v[0], "wall": v[1]}, evidence=evidence.get(k, {}))
                           for k, v in kinds.items()},
        "classification": {"robot_radius_m": radius, "margin_m": 0.1, "map": grid is not None,
                           "merge_distance_m": merge_distance, "obstacle_duration_s": lifetime},
        "ground_truth": truth,
        "latency_ms": lat,
        # a pair that never arrived counts as lost (late without end) in the percentiles, not left out
        "latency_missed": missed,
        "latency_ms_p50": percentile(lat + [math.inf] * missed, 50),
        "latency_ms_p99": percentile(lat + [math.inf] * missed, 99),
    }
    with open(args.out, "w") as f:
        json.dump(out, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
