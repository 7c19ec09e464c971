"""What the fleet scenarios (rostests, demo, bench) observe and do, on one ROS master.

A ``Fleet`` records, per robot: stuck events (sim time and true pose), recovery behaviours
announced on ``move_base/recovery_status``, every message the robot's handler sends to
(``to_fleet``) and gets from (``from_fleet``) its bridge, every plan, the true trajectory, and the
latest costmap; and the a-priori map (/map). It sends move_base goals, changes the simulator's
blocks and reads the handlers' obstacle lists (mosquitto's byte counters: broker_counters.py). Only observation: obstacles travel between robots through
MQTT alone (fleet.launch), the test node never forwards anything.

The same scenarios run on both hosts, named by the launch's /fleet/simulator: "stage" (stageros
with upstream move_base, move_base_fleet.launch) or "fleet_sim" (our stand-ins, fleet.launch).
Blocks move through fleet_sim's services there and through ``stage_blocks.BlockDriver`` on Stage;
the robots' views are fleet_nav's snapshots there and drawings of move_base's global costmap on
Stage.
"""
import math
import os
import threading
import time

import actionlib
import rospy
import yaml
from actionlib_msgs.msg import GoalStatus
from diagnostic_msgs.msg import DiagnosticArray
from map_msgs.msg import OccupancyGridUpdate
from move_base_msgs.msg import MoveBaseAction, RecoveryStatus
from nav_msgs.msg import OccupancyGrid, Odometry, Path
from std_msgs.msg import Empty, String
from std_srvs.srv import Empty as EmptySrv

from fleet_sim.srv import AddBlock, MoveBlock, RemoveBlock, Snapshot
from fleet_nav.goals import move_base_goal
from sharing_msgs.msg import RobotFootprintArray, SharedObstacle
from sharing_msgs.srv import ListObstacles

from fleet_tests import stage_blocks
from fleet_tests.errors import ScenarioError  # noqa: F401 (raised here; callers catch it from here)
from fleet_tests.run_picture import draw_costmap, draw_run

STATE_NAMES = {v: k for k, v in GoalStatus.__dict__.items() if k.isupper() and isinstance(v, int)}


def fleet_sharing():
    """Whether the fleet runs with sharing: /fleet/sharing (both fleet launches), else fleet_nav's own setting."""
    return bool(rospy.get_param("/fleet/sharing", rospy.get_param("/robot_0/move_base/sharing_enabled", True)))


def must_hear(robots, listener, size):
    """Names of the robots whose footprint adverts ``listener``'s bridge hears for sure at footprint_area_size
    ``size``: every other one within size - 0.5 m along both axes (a footprint's centroid, which places its
    advert, lies up to 0.5 m from the pose), or every other one without areas or before the poses are known."""
    others = [r for r in robots if r is not listener]
    here = listener.pose
    if size <= 0 or here is None:
        return [r.name for r in others]
    reach = size - 0.5
    return [r.name for r in others if r.pose is None
            or (abs(r.pose[0] - here[0]) <= reach and abs(r.pose[1] - here[1]) <= reach)]




def wait_for_sim_time(timeout=60.0):
    """Before rospy.init_node in a process started next to roslaunch: waits until the master is up
    and /use_sim_time is set, so that the node runs on the simulator's /clock (rospy reads the
    parameter once, at init)."""
    import rosgraph
    end = time.time() + timeout
    while time.time() < end:
        try:
            if rosgraph.Master("/fleet_scenario").getParam("/use_sim_time"):
                return
        except Exception:  # master not up yet, or parameter not set yet
            pass
        time.sleep(0.2)
    raise ScenarioError("no ROS master with /use_sim_time true after %.0f s" % timeout)


def load_facility(path=None):
    """goals.yaml of fleet_launch: goals, corridors and blocks; a bad file raises ScenarioError."""
    if path is None:
        import rospkg
        path = os.path.join(rospkg.RosPack().get_path("fleet_launch"), "worlds", "goals.yaml")
    try:
        with open(path) as f:
            data = yaml.safe_load(f)
        goals = {k: tuple(float(v) for v in val) for k, val in data["goals"].items()}
        corridors = {k: tuple(float(v) for v in val) for k, val in data["corridors"].items()}
        blocks = data["blocks"]
        bench_goals = [tuple(float(v) for v in g) for g in data.get("bench_goals", [])]
    except (OSError, yaml.YAMLError, KeyError, TypeError, ValueError) as err:
        raise ScenarioError("cannot read the facility description %s: %s" % (path, err)) from None
    for name, g in goals.items():
        if len(g) != 3 or not all(math.isfinite(v) for v in g):
            raise ScenarioError("%s: goal %s must be [x, y, yaw], got %r" % (path, name, g))
    return {"goals": goals, "corridors": corridors, "blocks": blocks, "bench_goals": bench_goals, "path": path}


def inside(rect, x, y, margin=0.0):
    return rect[0] - margin <= x <= rect[2] + margin and rect[1] - margin <= y <= rect[3] + margin


def cell_centre(msg, index):
    """World (x, y) of a costmap cell index of a SharedObstacle's grid."""
    ix, iy = index % msg.size_x, index // msg.size_x
    return msg.origin_x + (ix + 0.5) * msg.resolution, msg.origin_y + (iy + 0.5) * msg.resolution


class GoalClient(actionlib.SimpleActionClient):
    """actionlib's SimpleActionClient without its send_goal race (ros/actionlib#206).

    SimpleActionClient.send_goal sets ``self.gh = None``, publishes the goal and only then stores
    the new goal handle; the status and result topics are served by other threads, so a status
    that arrives in between (the action server answers within milliseconds, and a busy process
    lets the sending thread wait for the GIL) is handed to ``_handle_transition`` while ``self.gh``
    is still None: actionlib logs "[ERROR] Got a transition callback on a goal handle that we're not
    tracking" and drops the transition (PENDING/ACTIVE; had it been the result, wait_for_result
    would have waited in vain). make demo printed that line 1-5 times per run, right after a
    "sent to" line. Here sending and the callbacks share one lock: a callback that comes while
    the goal is being sent waits until its handle is stored, and is then handled as usual.

    Transitions of a goal this client replaced while it was still running (send_goal before it
    finished) are expected and ignored (logged at debug level); any other unknown handle still
    reaches actionlib's own error path."""

    def __init__(self, ns, action_spec):
        self._sending = threading.RLock()
        self._replaced = set()      # goal ids of unfinished goals that send_goal replaced
        super().__init__(ns, action_spec)

    def send_goal(self, goal, done_cb=None, active_cb=None, feedback_cb=None):
        with self._sending:
            old = self.gh
            if old is not None and old.get_comm_state() != actionlib.CommState.DONE:
                self._replaced.add(_goal_id(old))
            super().send_goal(goal, done_cb, active_cb, feedback_cb)

    def _handle_transition(self, gh):
        with self._sending:
            if gh != self.gh and _goal_id(gh) in self._replaced:
                rospy.logdebug("transition of replaced goal %s ignored", _goal_id(gh))
                return
            super()._handle_transition(gh)

    def _handle_feedback(self, gh, feedback):
        with self._sending:
            if gh != self.gh and _goal_id(gh) in self._replaced:
                return
            super()._handle_feedback(gh, feedback)


def _goal_id(gh):
    return gh.comm_state_machine.action_goal.goal_id.id


class Robot:
    def __init__(self, fleet, index):
        self.fleet = fleet
        self.name = "robot_%d" % index
        ns = "/" + self.name + "/"
        self.lock = fleet.lock
        self.stuck = []          # (sim time, x, y)
        self.recoveries = []     # (sim time, x, y, recovery behaviour name) from move_base/recovery_status
        self.to_fleet = []       # (sim time, SharedObstacle)
        self.from_fleet = []     # (sim time, SharedObstacle)
        self.expired = []        # (sim time, uuid)
        self.plans = []          # (sim time, [(x, y)])
        self.track = []          # (sim time, x, y) of the true pose, at most every 0.2 s
        self.costmap = None
        self.proposals_wall = []  # (wall time, SharedObstacle) this robot's layer proposed
        self.layer_in_wall = []   # (wall time, SharedObstacle) the handler gave this robot's layer
        self.layer_in = []        # (sim time, SharedObstacle) the same, in simulated time
        self.bridge_stats = {}    # latest coaty_bridge /diagnostics values
        self.pose = None
        self.distance = 0.0
        self.fleet_robots = ()    # names in the latest fleet_robots of this robot's bridge
        rospy.Subscriber(ns + "stuck_feedback", Empty, self._on_stuck, queue_size=10)
        rospy.Subscriber(ns + "move_base/recovery_status", RecoveryStatus, self._on_recovery, queue_size=10)
        rospy.Subscriber(ns + "to_fleet", SharedObstacle, self._append(self.to_fleet), queue_size=1000)
        rospy.Subscriber(ns + "from_fleet", SharedObstacle, self._append(self.from_fleet), queue_size=1000)
        rospy.Subscriber(ns + "expired_obstacles", String, self._on_expired, queue_size=100)
        # fleet_nav's plan, and upstream move_base's (navfn's)
        rospy.Subscriber(ns + "plan", Path, self._on_plan, queue_size=10)
        rospy.Subscriber(ns + "move_base/NavfnROS/plan", Path, self._on_plan, queue_size=10)
        rospy.Subscriber(ns + "base_pose_ground_truth", Odometry, self._on_pose, queue_size=10)
        # fleet_nav's global costmap, and upstream move_base's (published where publish_frequency > 0)
        rospy.Subscriber(ns + "global_costmap/costmap", OccupancyGrid, self._on_costmap, queue_size=1)
        rospy.Subscriber(ns + "move_base/global_costmap/costmap", OccupancyGrid, self._on_costmap, queue_size=1)
        # move_base sends its whole costmap once, then only the windows that changed
        rospy.Subscriber(ns + "move_base/global_costmap/costmap_updates", OccupancyGridUpdate,
                         self._on_costmap_update, queue_size=10)
        rospy.Subscriber(ns + "fleet_robots", RobotFootprintArray, self._on_fleet_robots, queue_size=2)
        rospy.Subscriber(ns + "obstacle_proposals", SharedObstacle, self._wall(self.proposals_wall), queue_size=100)
        rospy.Subscriber(ns + "shared_obstacles", SharedObstacle, self._on_layer_in, queue_size=1000)
        self.client = GoalClient(ns + "move_base", MoveBaseAction)
        self.list_srv = rospy.ServiceProxy(ns + "list_obstacles", ListObstacles)
        self.snapshot_srv = rospy.ServiceProxy(ns + "move_base/snapshot", Snapshot)

    def _append(self, target):
        def cb(msg):
            with self.lock:
                target.append((rospy.get_time(), msg))
        return cb

    def _wall(self, target):
        def cb(msg):
            with self.lock:
                target.append((time.time(), msg))
        return cb

    def _on_layer_in(self, msg):
        wall, sim = time.time(), rospy.get_time()
        with self.lock:
            self.layer_in_wall.append((wall, msg))
            self.layer_in.append((sim, msg))

    def _on_stuck(self, _msg):
        with self.lock:
            x, y = self.pose if self.pose else (float("nan"), float("nan"))
            self.stuck.append((rospy.get_time(), x, y))
        rospy.loginfo("scenario: %s stuck at (%.2f, %.2f)", self.name, x, y)

    def _on_recovery(self, msg):
        with self.lock:
            x, y = self.pose if self.pose else (float("nan"), float("nan"))
            self.recoveries.append((rospy.get_time(), x, y, msg.recovery_behavior_name))
        rospy.loginfo("scenario: %s recovery %d/%d %s at (%.2f, %.2f)", self.name, msg.current_recovery_number + 1,
                      msg.total_number_of_recoveries, msg.recovery_behavior_name, x, y)

    def _on_expired(self, msg):
        with self.lock:
            self.expired.append((rospy.get_time(), msg.data))

    def _on_plan(self, msg):
        with self.lock:
            self.plans.append((rospy.get_time(), [(p.pose.position.x, p.pose.position.y) for p in msg.poses]))

    def _on_pose(self, msg):
        x, y = msg.pose.pose.position.x, msg.pose.pose.position.y
        t = rospy.get_time()
        with self.lock:
            if self.pose is not None:
                self.distance += math.hypot(x - self.pose[0], y - self.pose[1])
            self.pose = (x, y)
            if not self.track or t - self.track[-1][0] >= 0.2:
                self.track.append((t, x, y))

    def _on_fleet_robots(self, msg):
        with self.lock:
            self.fleet_robots = tuple(r.robot for r in msg.robots)

    def fleet_robot_names(self):
        """The fleet robots this robot's bridge currently hears (its layer never shares them)."""
        with self.lock:
            return self.fleet_robots

    def pose_at(self, t):
        """True (x, y) at sim time t: the last track point at or before t (the first one before the track)."""
        with self.lock:
            before = [p for p in self.track if p[0] <= t]
            point = before[-1] if before else (self.track[0] if self.track else (t, float("nan"), float("nan")))
        return point[1], point[2]

    def _on_costmap(self, msg):
        with self.lock:
            self.costmap = msg

    def _on_costmap_update(self, update):
        """Applies one of costmap_2d's window updates to the latest whole costmap (a copy: readers keep theirs)."""
        with self.lock:
            grid = self.costmap
            if grid is None:
                return
            width, height = grid.info.width, grid.info.height
            if update.x + update.width > width or update.y + update.height > height or \
                    len(update.data) != update.width * update.height:
                rospy.logwarn("scenario: %s: costmap update %dx%d at (%d, %d) outside the %dx%d costmap, ignored",
                              self.name, update.width, update.height, update.x, update.y, width, height)
                return
            data = list(grid.data)
            for row in range(update.height):
                start = (update.y + row) * width + update.x
                data[start:start + update.width] = update.data[row * update.width:(row + 1) * update.width]
            fresh = OccupancyGrid()
            fresh.header = update.header
            fresh.info = grid.info
            fresh.data = data
            self.costmap = fresh

    def wait_ready(self, timeout):
        if not self.client.wait_for_server(rospy.Duration(timeout)):
            raise ScenarioError("%s/move_base action server not up after %.0f s" % (self.name, timeout))

    def send(self, goal_name):
        x, y, yaw = goal_name if isinstance(goal_name, tuple) else self.fleet.goal(goal_name)
        goal = move_base_goal(x, y, yaw)
        rospy.loginfo("scenario: %s sent to %s (%.2f, %.2f)", self.name, goal_name, x, y)
        # The time before the goal goes out: a plan the goal causes is recorded at or after it. Taken after
        # send_goal, a /clock tick in between (a loaded machine) left the only plan "before" the dispatch.
        sent = rospy.get_time()
        self.client.send_goal(goal)
        return sent

    def wait(self, timeout):
        """(finished, state name, status text) after at most timeout s of simulated time."""
        finished = self.client.wait_for_result(rospy.Duration(timeout))
        state = self.client.get_state()
        return finished, STATE_NAMES.get(state, str(state)), self.client.get_goal_status_text()

    def go(self, goal_name, timeout):
        self.send(goal_name)
        return self.wait(timeout)

    def obstacles(self):
        """{uuid: (sorted cells, version, rectangle)} from the handler's list service."""
        resp = self.list_srv()
        return {o.uuid: (tuple(sorted(o.marked_indexes)), o.version, tuple(round(v, 3) for v in o.rectangle_shape))
                for o in resp.obstacles}

    def shares(self):
        """First shares made by this robot (version 1, source = this robot), in order."""
        with self.lock:
            return [(t, m) for t, m in self.to_fleet if m.version == 1 and m.source == self.name]

    def forget_own_observations(self):
        """Resets the robot's obstacle layers, keeping the shared obstacles (the sharing layer's reset): upstream
        move_base's clear_costmaps service. fleet_nav resets its obstacle layer at every goal reached, so there
        it has been done already."""
        if self.fleet.simulator == "stage":
            rospy.ServiceProxy("/%s/move_base/clear_costmaps" % self.name, EmptySrv)()

    def snapshot(self, path):
        """This robot's view saved as a PNG; an object whose .message says where (or why not)."""
        if self.fleet.simulator == "fleet_sim":
            return self.snapshot_srv(path, False, 40.0)
        with self.lock:
            costmap = self.costmap
        if costmap is None:
            return Outcome(False, "%s: no global costmap received (move_base publishes it only with "
                                  "global_costmap/publish_frequency > 0)" % self.name)
        try:
            draw_costmap(path, costmap, "%s's global costmap" % self.name)
        except (OSError, ValueError) as err:
            return Outcome(False, "%s: %s" % (self.name, err))
        return Outcome(True, "%s's view: %s" % (self.name, path))


class Outcome:
    """What a picture request gave: like fleet_sim's Snapshot response (success, message)."""

    def __init__(self, success, message):
        self.success, self.message = success, message


class Fleet:
    def __init__(self, robots=2, facility=None):
        self.lock = threading.Lock()
        self.facility = facility or load_facility()
        # "stage" (move_base_fleet.launch) or "fleet_sim" (fleet.launch): who moves the blocks
        self.simulator = rospy.get_param("/fleet/simulator", "fleet_sim")
        if self.simulator not in ("stage", "fleet_sim"):
            raise ScenarioError("/fleet/simulator must be stage or fleet_sim, got %r" % (self.simulator,))
        self.robots = [Robot(self, i) for i in range(robots)]
        self.map = None          # the map server's /map (latched): the a-priori map
        self.stage_blocks = stage_blocks.BlockDriver(sorted(self.facility["blocks"])) \
            if self.simulator == "stage" else None
        self.removed = set()     # blocks taken away (fleet_sim) or parked in a wall (Stage)
        self.moved = {}          # name -> (x, y, yaw) of blocks put elsewhere (fleet_sim)
        self._add = rospy.ServiceProxy("/fleet_sim/add_block", AddBlock)
        self._move = rospy.ServiceProxy("/fleet_sim/move_block", MoveBlock)
        self._remove = rospy.ServiceProxy("/fleet_sim/remove_block", RemoveBlock)
        self._snapshot = rospy.ServiceProxy("/fleet_sim/snapshot", Snapshot)
        rospy.Subscriber("/diagnostics", DiagnosticArray, self._on_diagnostics, queue_size=100)
        rospy.Subscriber("/map", OccupancyGrid, self._on_map, queue_size=1)

    def _on_map(self, msg):
        with self.lock:
            self.map = msg

    def _on_diagnostics(self, msg):
        for status in msg.status:
            if status.name.startswith("coaty_bridge: "):
                name = status.name.split(": ", 1)[1]
                for r in self.robots:
                    if r.name == name:
                        with self.lock:
                            r.bridge_stats = {kv.key: kv.value for kv in status.values}

    def latencies(self):
        """Wall seconds from a robot's layer proposing an obstacle (detection) to each peer's layer
        receiving it authorised (peer costmap), one value per (obstacle, peer). The proposal is the
        one with the obstacle's rectangle (authorisation keeps it)."""
        out = []
        # (obstacle, peer) pairs whose obstacle never reached that peer's layer under its uuid (lost, or merged
        # there into another): the bench counts them as lost in its percentiles
        self.latency_pairs_missed = 0
        with self.lock:
            for r in self.robots:
                for _ts, share in [(t, m) for t, m in r.to_fleet if m.version == 1 and m.source == r.name]:
                    rect = tuple(share.rectangle_shape)
                    for peer in self.robots:
                        if peer is r:
                            continue
                        got = [t for t, m in peer.layer_in_wall if m.uuid == share.uuid]
                        if not got:
                            self.latency_pairs_missed += 1
                            continue
                        proposed = [t for t, p in r.proposals_wall if tuple(p.rectangle_shape) == rect and t <= got[0]]
                        if proposed:
                            out.append(got[0] - proposed[-1])
        return out

    def goal(self, name):
        try:
            return self.facility["goals"][name]
        except KeyError:
            raise ScenarioError("unknown goal %r; goals of %s: %s" % (
                name, self.facility["path"], ", ".join(sorted(self.facility["goals"])))) from None

    def corridor(self, name):
        try:
            return self.facility["corridors"][name]
        except KeyError:
            raise ScenarioError("unknown corridor %r; corridors: %s" % (
                name, ", ".join(sorted(self.facility["corridors"])))) from None

    def wait_ready(self, timeout=120.0):
        for r in self.robots:
            r.wait_ready(timeout)
        if self.simulator == "fleet_sim":
            for s in ("/fleet_sim/add_block", "/fleet_sim/remove_block", "/fleet_sim/snapshot"):
                rospy.wait_for_service(s, timeout)
        else:
            for name in self.facility["blocks"]:
                self.stage_blocks.pose(name, timeout)
            self.wait_until(lambda: self.map is not None, timeout, "the map server's /map")
        if fleet_sharing():
            for r in self.robots:
                rospy.wait_for_service(r.list_srv.resolved_name, timeout)
            # A robot's layer never shares the robots its bridge hears; one that moves before the others' footprint
            # adverts reached it may see them as obstacles (robot_1 shared robot_0 1.3 s after the start of Test 1).
            # A bridge hears the robots in the 3 x 3 footprint squares around its own: those within the square's
            # size along both axes for sure (farther ones it need not hear: no sensor of its robot reaches them).
            size = self.footprint_area_size()
            self.wait_until(lambda: all(set(must_hear(self.robots, r, size)) <= set(r.fleet_robot_names())
                                        for r in self.robots),
                            timeout, "every robot's bridge to hear the robots within footprint_area_size %g m of it"
                            % size)

    def footprint_area_size(self):
        """The bridges' footprint_area_size (the same on every robot of a fleet): robot_0's, else the default."""
        from coaty_bridge.client import BridgeConfig
        return float(rospy.get_param("/%s/coaty_bridge/footprint_area_size" % self.robots[0].name,
                                     BridgeConfig("x").footprint_area_size))


    def block_size(self, name):
        try:
            return tuple(float(v) for v in self.facility["blocks"][name]["size"])
        except KeyError:
            raise ScenarioError("unknown block %r; blocks: %s" % (name, ", ".join(sorted(self.facility["blocks"])))) \
                from None

    def remove_block(self, name):
        """Takes the block away: fleet_sim removes it; on Stage it is driven into a wall, out of every view."""
        if self.simulator == "fleet_sim":
            resp = self._remove(name)
            if not resp.success:
                raise ScenarioError("remove_block %s refused: %s" % (name, resp.message))
        else:
            with self.lock:
                grid = self.map
            try:
                where = self.stage_blocks.park(name, self.block_size(name), stage_blocks.map_occupancy(grid))
            except stage_blocks.BlockError as err:
                raise ScenarioError(str(err)) from None
            rospy.loginfo("scenario: block %s driven into the wall at (%.2f, %.2f)", name, where[0], where[1])
        with self.lock:
            self.removed.add(name)
            self.moved.pop(name, None)
        rospy.loginfo("scenario: block %s removed", name)

    def add_block(self, name, x, y, yaw, sx, sy):
        """Puts a block (back) at (x, y, yaw). On Stage the world's block is driven there, so the size must be
        the world's."""
        if self.simulator == "fleet_sim":
            resp = self._add(name, x, y, yaw, sx, sy)
            if not resp.success:
                raise ScenarioError("add_block %s refused: %s" % (name, resp.message))
        else:
            size = self.block_size(name)
            if abs(size[0] - sx) > 1e-6 or abs(size[1] - sy) > 1e-6:
                raise ScenarioError("add_block %s: Stage cannot resize the world's %.2f x %.2f m block to "
                                    "%.2f x %.2f m" % (name, size[0], size[1], sx, sy))
            try:
                self.stage_blocks.place(name, (x, y, yaw))
            except stage_blocks.BlockError as err:
                raise ScenarioError(str(err)) from None
        with self.lock:
            self.removed.discard(name)
            self.moved[name] = (x, y, yaw)
        rospy.loginfo("scenario: block %s added at (%.2f, %.2f, %.2f rad)", name, x, y, yaw)

    def present_blocks(self):
        """The blocks in the world now, as ground_truth takes them: [{"pose": [x, y, yaw], "size": [sx, sy]}].
        On Stage their poses are Stage's ground truth; on fleet_sim what the scenario put where."""
        out = []
        for name, b in sorted(self.facility["blocks"].items()):
            with self.lock:
                if name in self.removed:
                    continue
                pose = self.moved.get(name)
            if self.simulator == "stage":
                pose = self.stage_blocks.pose(name)
            out.append({"name": name, "pose": list(pose or b["pose"]), "size": list(self.block_size(name))})
        return out

    def world_snapshot(self, path, pixels_per_metre=40.0):
        if self.simulator == "fleet_sim":
            return self._snapshot(path, True, pixels_per_metre)
        with self.lock:
            grid = self.map
            trails = {r.name: list(r.track) for r in self.robots}
        if grid is None:
            return Outcome(False, "no /map received: no picture of the world")
        facility = dict(self.facility, blocks={b["name"]: b for b in self.present_blocks()})
        try:
            draw_run(path, grid, facility, trails, [], "the world (Stage ground truth)")
        except (OSError, ValueError) as err:
            return Outcome(False, "world picture: %s" % err)
        return Outcome(True, "the world: %s" % path)

    def wait_until(self, predicate, timeout, what, period=0.2):
        """Waits (simulated time) until predicate() is true; raises ScenarioError naming what."""
        end = rospy.get_time() + timeout
        while not rospy.is_shutdown():
            value = predicate()
            if value:
                return value
            if rospy.get_time() > end:
                raise ScenarioError("timed out after %.0f s of simulated time waiting for %s" % (timeout, what))
            rospy.sleep(period)
        raise ScenarioError("shut down while waiting for %s" % what)

    def lists_identical(self):
        """(identical, per-robot lists) of the handlers' obstacle lists."""
        lists = [r.obstacles() for r in self.robots]
        return all(l == lists[0] for l in lists[1:]), lists


def entered(points, rect, margin=0.0):
    """Points (x, y) or (t, x, y) of a path that lie inside rect."""
    out = []
    for p in points:
        x, y = p[-2], p[-1]
        if inside(rect, x, y, margin):
            out.append(p)
    return out


def percentile(values, q):
    if not values:
        return float("nan")
    values = sorted(values)
    k = (len(values) - 1) * q / 100.0
    lo, hi = int(math.floor(k)), int(math.ceil(k))
    if lo == hi or values[hi] == values[lo]:
        return values[lo]   # also an infinite one (a lost sample) without inf - inf
    return values[lo] + (values[hi] - values[lo]) * (k - lo)
