"""One run of the lifecycle bench (issue 26): python3 -m fleet_tests.lifecycle --delay S --out FILE
[--remove-after R], against fleet.launch layout:=corridors with 2 robots on its own master
(tests/scripts/bench_lifecycle starts it).

robot_0 (the leader) is sent to goal_0 straight through the short corridor, which block_short
closes. The reference moment is when it found the block: its first share with sharing on, and with
sharing off (nothing is shared) the moment its ground-truth pose first came within obstacle_range
of the block, which is when the layer marks it. robot_1 (the follower) is sent to goal_1 `delay`
simulated s later.

Arrival-interval mode (no --remove-after): did the follower avoid the block that is still there
(never crossed the short corridor's mouth), did it rediscover it (share cells on it), its time to
goal, and whether its handler still held the leader's obstacle when it was sent.

Block-removed mode (--remove-after R): the block is taken away R s after the reference moment,
while nobody is near it. Then the follower is a "stale detour" when it is sent while the obstacle is
still held and takes the long corridor; the run also reports, once a robot's sensors cover the
place (the follower driving by, or nobody), when that robot's handler deleted the obstacle and when
every robot's costmap was free there (issue 26: within 1 s of the first clearing). From message receipts
(`Receipts`, subscribers, no polling) also: the moment that robot's handler ended the obstacle (the
update after which no cell of it is present left it for the fleet) to the moment the last robot's
layer dropped it (the update or expiry after which that layer holds no present cell of it).

Writes FILE (JSON). Pure helpers: tests/test/test_lifecycle_metrics.py."""
import argparse
import json
import sys
import threading
import time


def found_block_at(track, block, reach):
    """Sim time of the first track point (t, x, y) within reach (m) of the block's rectangle, or None."""
    from fleet_tests.ground_truth import distance_to_block
    for t, x, y in track:
        if distance_to_block(x, y, block) <= reach:
            return t
    return None


def costmap_free_at(grid, cells):
    """Whether none of the world points `cells` is lethal (100) in an OccupancyGrid costmap (None: no costmap)."""
    if grid is None:
        return None
    res, ox, oy, w = grid.info.resolution, grid.info.origin.position.x, grid.info.origin.position.y, grid.info.width
    for x, y in cells:
        ix, iy = int((x - ox) / res), int((y - oy) / res)
        if 0 <= ix < w and 0 <= iy < grid.info.height and grid.data[iy * w + ix] == 100:
            return False
    return True


def present_after(messages):
    """The cells of one obstacle present after `messages` [(marked, cleared, version, source)], by the handler's
    and the layer's convergence rule: an update with stamp S = (version, source) marks each marked cell whose
    stamp is < S, then clears each cleared cell whose stamp is <= S (sharing_handler_py README)."""
    stamps = {}
    for marked, cleared, version, source in messages:
        stamp = (version, source)
        for cell in marked:
            if cell not in stamps or stamps[cell][0] < stamp:
                stamps[cell] = (stamp, True)
        for cell in cleared:
            if cell not in stamps or stamps[cell][0] <= stamp:
                stamps[cell] = (stamp, False)
    return {cell for cell, (_stamp, present) in stamps.items() if present}


def emptied_at(events, after=None):
    """events [(sim time, kind, marked, cleared, version, source)] of one obstacle at one node, in receipt order
    (kind "update" applies its cells, "expired" drops them all): the index of the first event at or after sim time
    `after` after which no cell is present while some was just before it, or None."""
    applied, shown = [], False
    for k, (t, kind, marked, cleared, version, source) in enumerate(events):
        if kind == "expired":
            applied, now = [], False
        else:
            applied.append((marked, cleared, version, source))
            now = bool(present_after(applied))
        if shown and not now and (after is None or t >= after):
            return k
        shown = now
    return None


class Receipts:
    """Every obstacle message of each robot's handler and layer, with the sim and wall time of its receipt
    here (subscribers: no polling): per robot, what its handler sent (to_fleet) and got (from_fleet), what its
    layer got (shared_obstacles, expired_obstacles) and made itself (obstacle_updates)."""

    TOPICS = {"to_fleet": "handler", "from_fleet": "handler", "shared_obstacles": "layer",
              "obstacle_updates": "layer", "expired_obstacles": "layer"}

    def __init__(self, robots):
        import rospy
        from sharing_msgs.msg import SharedObstacle
        from std_msgs.msg import String
        self.lock = threading.Lock()
        self.events = {(r, node): [] for r in robots for node in ("handler", "layer")}
        for r in robots:
            for topic, node in self.TOPICS.items():
                kind = String if topic == "expired_obstacles" else SharedObstacle
                rospy.Subscriber("/%s/%s" % (r, topic), kind, self._cb(r, node, topic), queue_size=1000)

    def _cb(self, robot, node, topic):
        import rospy

        def cb(msg):
            sim, wall = rospy.get_time(), time.time()
            if topic == "expired_obstacles":
                event = (msg.data, sim, wall, "expired", (), (), 0, "")
            else:
                event = (msg.uuid, sim, wall, "update", tuple(msg.marked_indexes), tuple(msg.cleared_indexes),
                         msg.version, msg.source)
            with self.lock:
                self.events[(robot, node)].append(event)
        return cb

    def of(self, robot, node, uuid):
        """[(sim time, wall time, kind, marked, cleared, version, source)] of uuid at that node, in receipt order."""
        with self.lock:
            return [e[1:] for e in self.events[(robot, node)] if e[0] == uuid]


def end_to_last_drop(timelines, after=None):
    """From the clearing robot's handler ending the obstacle to the last robot's layer dropping it.

    timelines: {"handler": {robot: events}, "layer": {robot: events}}, each event (sim time, wall time, kind, marked,
    cleared, version, source) of the obstacle in receipt order (Receipts.of). A handler ended it with the first
    message it sent or got (at or after sim time `after`) after which none of its cells is present; the clearing
    robot is the source of that message (its own update: the peers' handlers follow when it reaches them; the order
    in which one observer receives different robots' topics says nothing about which came first), and the end is
    when the clearing robot's handler sent it. A robot's layer dropped it with the first update it got or made, or
    the expiry, after which it holds none. {"clearer": robot or None, "ended": sim s or None,
    "dropped": {robot: sim s or None}, "end_to_last_drop_s": sim s, "end_to_last_drop_wall_s": wall s (both None
    unless the clearing robot's handler ended it and every layer dropped it)}."""
    def first(events):
        k = emptied_at([(e[0],) + tuple(e[2:]) for e in events], after)
        return None if k is None else events[k]
    ended = {r: first(events) for r, events in sorted(timelines["handler"].items())}
    sources = sorted({e[6] for e in ended.values() if e is not None and e[2] == "update"})
    clearer = sources[0] if len(sources) == 1 and sources[0] in ended else None
    end = ended[clearer] if clearer else None
    drops = {r: first(events) for r, events in sorted(timelines["layer"].items())}
    out = {"clearer": clearer, "ended": end[0] if end else None,
           "dropped": {r: d and d[0] for r, d in drops.items()}, "end_to_last_drop_s": None,
           "end_to_last_drop_wall_s": None}
    if end and drops and all(d is not None for d in drops.values()):
        out["end_to_last_drop_s"] = max(d[0] for d in drops.values()) - end[0]
        out["end_to_last_drop_wall_s"] = max(d[1] for d in drops.values()) - end[1]
    return out


def check_the_place(fleet, robot, uuid, timeout, receipts=None):
    """Sends robot to look_down, where its beams cover the removed block's place, and waits until no robot
    holds the obstacle any more. {"first_clear": sim time of robot's first update clearing cells of it,
    "deleted": {robot: sim time its handler deleted it}, "spread_s": last deletion - first clear,
    "costmaps_free": {robot: whether its costmap is free at the obstacle's cells 1 s after the last deletion}},
    and with `receipts` (a Receipts made before the share) end_to_last_drop's figures from the dispatch on,
    under "receipts"."""
    import rospy
    from fleet_tests.scenario import ScenarioError, cell_centre
    sent = robot.send("look_down")
    cells = [cell_centre(m, i) for r in fleet.robots for _t, m in r.to_fleet if m.uuid == uuid for i in m.marked_indexes]
    # when each robot stopped listing it (evidence: no message to the layer, the list is the truth)
    deleted = {r.name: None for r in fleet.robots}

    def all_gone():
        now = rospy.get_time()
        for r in fleet.robots:
            if deleted[r.name] is None and uuid not in r.obstacles():
                deleted[r.name] = now
        return all(t is not None for t in deleted.values())
    try:
        fleet.wait_until(all_gone, timeout, "the obstacle's end", period=0.1)
    except ScenarioError as err:
        print("lifecycle: %s" % err)
    robot.wait(max(1.0, sent + timeout - rospy.get_time()))
    with fleet.lock:
        clears = [t for t, m in robot.to_fleet if m.uuid == uuid and m.cleared_indexes and t >= sent]
    done = [t for t in deleted.values() if t is not None]
    if done:
        fleet.wait_until(lambda: rospy.get_time() >= max(done) + 1.0, 10.0, "1 s after the deletion")
    out = {"first_clear": clears[0] if clears else None, "deleted": deleted,
           "spread_s": (max(done) - clears[0]) if clears and len(done) == len(deleted) else None,
           "costmaps_free": {r.name: costmap_free_at(r.costmap, cells) for r in fleet.robots}}
    if receipts is not None:
        names = [r.name for r in fleet.robots]
        out["receipts"] = end_to_last_drop({node: {n: receipts.of(n, node, uuid) for n in names}
                                            for node in ("handler", "layer")}, after=sent)
    return out


def main(argv=None):
    import rospy
    from fleet_tests.bench import crossed_mouth
    from fleet_tests.ground_truth import on_block, run_figures
    from fleet_tests.scenario import Fleet, ScenarioError, cell_centre, fleet_sharing, load_facility, wait_for_sim_time

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--delay", type=float, required=True, help="simulated s from the leader finding the block "
                        "to the follower's dispatch")
    parser.add_argument("--remove-after", type=float, default=None,
                        help="take the block away this many simulated s after the leader found it")
    parser.add_argument("--goal-timeout", type=float, default=400.0)
    parser.add_argument("--out", required=True)
    args = parser.parse_args(rospy.myargv(argv or sys.argv)[1:])
    wait_for_sim_time()
    rospy.init_node("bench_lifecycle_run")
    try:
        fleet = Fleet(2, facility=load_facility(rospy.get_param("/fleet/goals", None)))
        receipts = Receipts([r.name for r in fleet.robots])
        fleet.wait_ready(180.0)
    except ScenarioError as err:
        print("lifecycle: %s" % err)
        return 1
    sharing = fleet_sharing()
    leader, follower = fleet.robots
    block = fleet.facility["blocks"]["block_short"]
    short = fleet.corridor("short")
    reach = float(rospy.get_param("/robot_0/move_base/global_costmap/obstacle_range", 2.5))
    leader_sent = leader.send("goal_0")

    def found():
        if sharing:
            shares = leader.shares()
            return shares[0][0] if shares else None
        with fleet.lock:
            return found_block_at(list(leader.track), block, reach)
    try:
        found_at = fleet.wait_until(found, 200.0, "robot_0 to find block_short")
    except ScenarioError as err:
        print("lifecycle: %s" % err)
        return 1
    uuid = leader.shares()[0][1].uuid if sharing else None
    removed_at = None
    if args.remove_after is not None:
        fleet.wait_until(lambda: rospy.get_time() >= found_at + args.remove_after, args.remove_after + 10.0,
                         "the removal time")
        fleet.remove_block("block_short")
        removed_at = rospy.get_time()
    fleet.wait_until(lambda: rospy.get_time() >= found_at + args.delay, args.delay + 10.0, "the dispatch time")
    held_at_dispatch = bool(uuid and uuid in follower.obstacles())
    follower_sent = follower.send("goal_1")
    result = follower.wait(args.goal_timeout)
    leader_result = leader.wait(max(1.0, leader_sent + args.goal_timeout - rospy.get_time()))
    verify = None
    if removed_at is not None and uuid:
        verify = check_the_place(fleet, leader, uuid, args.goal_timeout, receipts)
    with fleet.lock:
        track = [(t, x, y) for t, x, y in follower.track if t >= follower_sent]
        messages = [(t, m.source, m.resolution, [cell_centre(m, i) for i in m.marked_indexes])
                    for r in fleet.robots for t, m in r.to_fleet if m.source == r.name and m.marked_indexes]
        follower_on_block = [t for t, source, res, points in messages if source == follower.name and t >= follower_sent
                             and any(on_block(x, y, res, block) for x, y in points)]
    entered = crossed_mouth(track, short)
    out = {
        "sharing": sharing, "delay_s": args.delay, "remove_after_s": args.remove_after,
        "found_at": found_at, "follower_sent": follower_sent, "removed_at": removed_at,
        "held_at_dispatch": held_at_dispatch,
        "follower_entered_blocked_corridor": entered,
        # found the block itself: shared it anew (sharing on), or drove up to it (off: nothing to share)
        "follower_rediscovered": removed_at is None and (bool(follower_on_block) if sharing else entered),
        "follower_reached": result[1] == "SUCCEEDED",
        "follower_time_to_goal": (rospy.get_time() - follower_sent) if result[1] == "SUCCEEDED" else None,
        "follower_distance_m": sum(((b[1] - a[1]) ** 2 + (b[2] - a[2]) ** 2) ** 0.5 for a, b in zip(track, track[1:])),
        "leader_reached": leader_result[1] == "SUCCEEDED",
        "obstacle_duration_s": rospy.get_param("/robot_0/sharing_handler/obstacle_duration", None),
        "ground_truth": run_figures([m for m in messages if removed_at is None or m[0] < removed_at],
                                    {r.name: list(r.track) for r in fleet.robots}, {"block_short": block},
                                    fleet.facility["corridors"], 0.2),
    }
    if removed_at is not None:
        # a stale detour: sent while the removed block's obstacle was still held, and not through the short corridor
        out["stale_detour"] = bool(held_at_dispatch and not entered)
        out["stale_detour_s"] = (follower_sent - removed_at) if out["stale_detour"] else 0.0
        out["verification"] = verify
    with open(args.out, "w") as f:
        json.dump(out, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
