"""The fleet of real nodes that test_attacks_nodes.py attacks: one private rosmaster, the secure broker, three
robots (sharing_handler and coaty_bridge nodes with robot.launch's parameters), fleet_probe.py watching them,
and the attacker's raw Coaty peer under robot_3's login. The module docstring of test_attacks_nodes.py says
what each case checks."""
import functools
import json
import math
import os
import subprocess
import sys
import time
import uuid as uuidlib

from coaty_bridge import codec, footprint as fp
from coaty_bridge.identity import identity_for
from coaty_bridge.topics import Topic

import polling
from test_secure_default import Lines, Peer, close_peers, launch_bridge_params, start_secure_broker

NS = "fleet"
OT = codec.DEFAULT_OBJECT_TYPE
ROBOTS = ("robot_0", "robot_1", "robot_2")
ATTACKER = "robot_3"                    # its login is the attacker's; no nodes run under it
DURATION = 1200                         # robot.launch's obstacle_duration
RES, OX, OY, SX, SY = 0.05, -5.0, -2.5, 200, 100   # fleet_probe's map (10 m x 5 m)
HANDLER = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
                       "sharing_handler_py", "scripts", "sharing_handler")
WAIT = 30.0                             # generous bound on a condition: the test waits for it
# where each robot stands (fleet_probe publishes its footprint there; its bridge advertises it with a 4 m reach)
ROBOT_POSES = {"robot_0": (0.0, -1.0), "robot_1": (2.5, -1.0), "robot_2": (-2.5, -1.0)}
ATTACKER_POSE = (0.0, 1.5)              # robot_3's, as the attacker advertises it (it may move: attacker_at)
REACH = 4.0
# good obstacles: more than merge_distance (0.5 m) from each other, from the fresh ones (y 0..0.3)
# and from the attacks (y >= 1.0), within their robot's reach
GOOD = [("robot_0", [-3.5, -2.0, -3.2, -1.7]), ("robot_0", [-1.0, -2.0, -0.7, -1.7]),
        ("robot_1", [3.0, -2.0, 3.3, -1.7])]
LATENCIES = []


def cell(x, y):
    return int((y - OY) / RES) * SX + int((x - OX) / RES)


wait_until = functools.partial(polling.wait_until, timeout=WAIT)


def _gap(a, b):
    """Distance between rectangles (x0, y0, x1, y1); 0 when they overlap or touch."""
    return math.hypot(max(0.0, a[0] - b[2], b[0] - a[2]), max(0.0, a[1] - b[3], b[1] - a[3]))


def evil(**fields):
    """A valid obstacle of the attacker (source robot_3, its own name), stamped now, 1 cell at (0, 1.2)."""
    values = dict(uuid=str(uuidlib.uuid4()), source=ATTACKER, version=1, stamp=time.time(), frame_id="map",
                  deadline=60, rectangle=(0.0, 1.2, 0.05, 1.25), resolution=RES, origin_x=OX, origin_y=OY,
                  size_x=SX, size_y=SY, marked=(cell(0.01, 1.21),), cleared=())
    values.update(fields)
    return codec.ObstacleUpdate(**values)


class NodeFleet:
    def __init__(self, graph, credentials, log_dir):
        self.graph, self.credentials = graph, credentials
        start_secure_broker(self, graph, ROBOTS + (ATTACKER,), credentials)
        self.peers = [self.watcher]
        wait_until(self.watcher.settled, "the watcher")
        assert self.watcher.accepted
        self.login = identity_for(NS, ATTACKER)
        self.advert_id = str(uuidlib.uuid4())
        self.connect_attacker()
        self.bridges, self.logs, self.handlers = {}, {}, {}
        for robot in ROBOTS:
            log = open(os.path.join(log_dir, robot + "_handler.log"), "w")
            self.handlers[robot] = subprocess.Popen(
                [sys.executable, HANDLER, "__ns:=" + robot, "__name:=sharing_handler",
                 "_obstacle_duration:=%d" % DURATION], env=graph.env, stdout=log, stderr=subprocess.STDOUT)
            graph.nodes.append(self.handlers[robot])
            self.bridges[robot] = graph.bridge(robot, *launch_bridge_params(robot, credentials))
            self.logs[robot] = Lines(self.bridges[robot])
        self.probe = graph.json_lines_process(
            "fleet_probe", [sys.executable, os.path.join(graph.PKG, "test", "fleet_probe.py")] + list(ROBOTS),
            env=graph.env)
        graph.nodes.append(self.probe)
        self.probe.expect(lambda e: e.get("event") == "ready", timeout=60, what="probe ready")
        self.next_id = 0
        self.fresh_count = 0
        self.attacker_pose = ATTACKER_POSE
        for robot in ROBOTS:
            self.command({"cmd": "pose", "robot": robot, "x": ROBOT_POSES[robot][0], "y": ROBOT_POSES[robot][1]})
        for robot in ROBOTS:
            wait_until(lambda r=robot: self.identity_adverts(r), robot + "'s bridge logged in", timeout=60)
            wait_until(lambda r=robot: self.list_of(r) is not None, robot + "'s first list", timeout=60)
        # every bridge hears every other's heartbeats (subscribed and joined)
        wait_until(lambda: all(self.status("coaty_bridge: " + r, after=0) and
                               self.status("coaty_bridge: " + r)["values"].get("peers_heard") == "2"
                               for r in ROBOTS), "every bridge hearing both peers", timeout=60)
        # every bridge has heard the others' footprints (the evidence their obstacles are judged by)
        wait_until(lambda: all(set(ROBOTS) - {r} <= set(self.fleet_robots_of(r)) for r in ROBOTS),
                   "every bridge hearing the others' footprints", timeout=60)
        self.good = self._share_good()

    def connect_attacker(self):
        """(Re)connects the attacker under robot_3's login."""
        self.attacker = Peer(self.port, *self.creds.login(ATTACKER))
        self.peers.append(self.attacker)
        wait_until(self.attacker.settled, "the attacker's login")
        assert self.attacker.accepted, "robot_3's valid login was refused"

    # ------------------------------------------------------------------ observation

    def identity_adverts(self, robot):
        return [t for t in self.watcher.topics() if t.startswith("coaty/3/%s/ADV:Identity/" % NS)
                and t.endswith(identity_for(NS, robot))]

    def events(self, kind):
        with self.probe._cond:
            return [e for e in self.probe.events if e.get("event") == kind]

    def fleet_robots_of(self, robot):
        lists = [e["robots"] for e in self.events("fleet_robots") if e["robot"] == robot]
        return lists[-1] if lists else []

    def list_of(self, robot):
        lists = [e for e in self.events("list") if e["robot"] == robot]
        return lists[-1] if lists else None

    def held(self, robot):
        """uuid -> (source, rectangle, cells) of robot's last list."""
        last = self.list_of(robot)
        return {u: (last["sources"][u], last["rects"][u], last["cells"][u]) for u in last["uuids"]}

    def deadlines(self, robot):
        return dict(self.list_of(robot)["deadlines"])

    def expiries(self, robot):
        """uuid -> when (s, wall clock) its lease runs out on ``robot``: the list's stamp + its deadline (whole
        seconds: within 1 s). Unlike the deadline, comparable between lists of different times."""
        last = self.list_of(robot)
        return {u: last["stamp"] + d for u, d in last["deadlines"].items()}

    def status(self, name, after=0):
        """The newest diagnostics status called ``name`` among the probe's events from index ``after``."""
        with self.probe._cond:
            events = self.probe.events[after:]
        for event in reversed(events):
            if event.get("event") == "diagnostics":
                for status in event["status"]:
                    if status["name"] == name:
                        return status
        return None

    def mark(self):
        with self.probe._cond:
            return len(self.probe.events)

    def counter(self, name, key):
        status = self.status(name)
        return int(status["values"].get(key, "0")) if status else 0

    def counters(self, node, key):
        return {r: self.counter(self.node_name(node, r), key) for r in ROBOTS}

    @staticmethod
    def node_name(node, robot):
        return "coaty_bridge: " + robot if node == "bridge" else "sharing_handler (%s)" % robot

    def wait_counted(self, node, key, before, robots=ROBOTS, at_least=1):
        """Waits until ``key`` in every robot's ``node`` diagnostics rose by ``at_least`` over ``before``."""
        wait_until(lambda: all(self.counter(self.node_name(node, r), key) >= before[r] + at_least for r in robots),
                   "%s diagnostics naming %s on %s (before %s, now %s)" % (
                       node, key, robots, before, self.counters(node, key)))

    # ------------------------------------------------------------------ actions

    def command(self, cmd):
        self.next_id += 1
        cmd["id"] = self.next_id
        self.probe.send(cmd)
        return self.probe.expect(lambda e: e.get("event") == "reply" and e.get("id") == cmd["id"],
                                 timeout=WAIT, what="reply to %s" % cmd["cmd"])

    def add(self, robot, rect):
        reply = self.command({"cmd": "add", "robot": robot, "rect": rect})
        assert reply["success"], reply
        return reply["uuid"]

    def _share_good(self):
        uuids = [self.add(robot, rect) for robot, rect in GOOD]
        for robot in ROBOTS:
            wait_until(lambda r=robot: set(uuids) <= set(self.list_of(r)["uuids"]),
                       "%s holding the good obstacles" % robot)
        return uuids

    def snapshot(self):
        return {r: ({u: h for u, h in self.held(r).items() if u in self.good}, self.deadlines(r)) for r in ROBOTS}

    def assert_good_unchanged(self, before):
        for robot in ROBOTS:
            held = self.held(robot)
            good, deadlines = before[robot]
            assert {u: held.get(u) for u in self.good} == good, "%s: a good obstacle was lost or changed" % robot
            now = self.deadlines(robot)
            for u in self.good:
                assert now[u] <= DURATION, "%s: %s has a lease of %d s" % (robot, u, now[u])

    def fresh_obstacle_reaches_everyone(self, what):
        """robot_0 adds an obstacle; every robot must list it. Returns the latency (s) from the
        add_obstacle command to the last robot's list holding it (receipt in this process)."""
        x = -3.2 + 0.8 * (self.fresh_count % 9)   # within robot_0's reach
        self.fresh_count += 1
        start = time.monotonic()
        uuid = self.add("robot_0", [x, 0.0, x + 0.2, 0.2])
        wait_until(lambda: all(uuid in self.list_of(r)["uuids"] for r in ROBOTS),
                   "the fresh obstacle after %s on every robot" % what)
        latency = time.monotonic() - start
        LATENCIES.append((what, latency))
        print("fresh obstacle after %s reached every robot in %.3f s" % (what, latency))
        if os.environ.get("FLEET_ASSERT_LATENCY") == "1":
            assert latency <= 1.0, "fresh obstacle after %s took %.2f s" % (what, latency)
        return latency

    def publish(self, topic, payload):
        """The attacker publishes raw; an obstacle's rectangle is remembered (the next sentinel keeps clear of it)."""
        try:
            rect = json.loads(payload)["object"]["rectangle"]
            self.its_rectangles = getattr(self, "its_rectangles", []) + [tuple(float(v) for v in rect)]
        except Exception:
            pass            # not an obstacle advert, or not one the codec writes
        self.attacker.publish(topic, payload)

    def attacker_at(self, x, y):
        """The attacker's advertised pose from now on (it advertises it before each message)."""
        self.attacker_pose = (x, y)

    def advertise_pose(self, pose=None, points=None, robot=ATTACKER, stamp=None):
        """The attacker advertises robot_3's footprint (a 0.6 m square at its pose, or ``points``), stamped now (or
        ``stamp``), with a 4 m reach, under the plain objectType every bridge hears: its evidence (issue 43)."""
        x, y = pose or self.attacker_pose
        points = points or ((x - 0.3, y - 0.3), (x + 0.3, y - 0.3), (x + 0.3, y + 0.3), (x - 0.3, y + 0.3))
        footprint = fp.RobotFootprint(robot=robot, stamp=time.time() if stamp is None else stamp, frame_id="map",
                                      points=points, reach=REACH)
        self.publish(str(Topic(NS, "ADV", self.login, object_type=fp.DEFAULT_FOOTPRINT_OBJECT_TYPE)),
                     fp.footprint_payload(footprint, self.advert_id))

    def sentinel(self):
        """A valid obstacle of the attacker's own, sent after an attack and waited for on every robot:
        a sender's messages are delivered in order (its own queue in each bridge, one from_fleet topic),
        so once every robot lists it the attack before it has been handled or dropped everywhere, and
        the outcome can be judged (rather than only the counter that names it). Placed where it merges with
        nothing (_sentinel_spot)."""
        self.sentinels = getattr(self, "sentinels", 0) + 1
        x, y = self._sentinel_spot()
        # a short lease: the spots free up again
        update = evil(rectangle=(x, y, x + 0.05, y + 0.05), marked=(cell(x + 0.01, y + 0.01),), deadline=20)
        # an obstacle that covered the cell already (an earlier sentinel at this spot) says nothing about this one
        # until it changes: the sentinel's own uuid listed, or merged into one that its new cell made grow
        covering_before = {r: self._absorbers(r, x, y) for r in ROBOTS}
        self.advertise(update)
        wait_until(lambda: all(update.uuid in self.list_of(r)["uuids"] or
                               any(covering_before[r].get(u) != now for u, now in self._absorbers(r, x, y).items())
                               for r in ROBOTS),
                   "the attacker's sentinel obstacle on every robot")

    def _sentinel_spot(self):
        """A cell within the attacker's reach, on the map, more than merge_distance (0.5 m) + 0.1 from every
        obstacle of robot_3's any robot lists, from what the attacker sent since (its_rectangles) and from the good
        and fresh obstacles: robot_3's own obstacles merge (one creator), and the sentinel must not merge into one
        that an attack just changed."""
        ax, ay = self.attacker_pose
        near = [tuple(rect) for r in ROBOTS for u, rect in self.list_of(r)["rects"].items()
                if self.list_of(r)["sources"][u] == ATTACKER]
        # (a rectangle wider than one robot sees across, 2 * (4 m + 0.5 m), is refused by every receiver)
        near += [r for r in getattr(self, "its_rectangles", []) if max(r[2] - r[0], r[3] - r[1]) <= 9.0]
        self.its_rectangles = []
        # not on the good obstacles nor in the fresh obstacles' band (other creators: no merge, but no overlap)
        apart = [tuple(r) for _, r in GOOD] + [(-5.0, -0.05, 5.0, 0.35)]
        spots = sorted(((0.35 * i, 0.4 * j + (0.1 if j > 0 else -0.1)) for i in range(-9, 10) for j in range(-7, 7)
                        if math.hypot(0.35 * i, 0.4 * j) <= 3.0), key=lambda d: (abs(d[1]), abs(d[0])))
        for dx, dy in spots:
            x, y = ax + dx, ay + dy
            if not (OX + 0.2 <= x <= OX + SX * RES - 0.3 and OY + 0.2 <= y <= OY + SY * RES - 0.3):
                continue
            spot = (x, y, x + 0.05, y + 0.05)
            if all(_gap(spot, r) > 0.6 for r in near) and all(_gap(spot, r) > 0.1 for r in apart):
                return x, y
        raise AssertionError("no spot for a sentinel near %s: robot_3's obstacles all around" % (self.attacker_pose,))

    def _absorbers(self, robot, x, y):
        """uuid -> (rectangle, cells) of listed obstacles covering the sentinel's cell (it may have merged into one)."""
        last = self.list_of(robot)
        return {u: (tuple(rect), last["cells"][u]) for u, rect in last["rects"].items()
                if rect[0] <= x + 0.01 <= rect[2] and rect[1] <= y + 0.01 <= rect[3] and u not in self.good}

    def advertise(self, update, source_id=None, **raw):
        self.advertise_pose()
        obj = codec.obstacle_to_object(update, OT)
        obj.update(raw)
        self.publish(str(Topic(NS, "ADV", source_id or self.login, object_type=OT)),
                     json.dumps({"object": obj}).encode())

    def close(self):
        close_peers(self.peers)
        print("fresh-obstacle latencies (s): " + ", ".join("%s %.3f" % (w, l) for w, l in LATENCIES))
