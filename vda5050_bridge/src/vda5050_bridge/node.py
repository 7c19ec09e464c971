"""rospy node ``vda5050_bridge`` (one per robot, in its namespace): a thin shell around
``core.BridgeCore`` and ``client.VdaMqttClient``.

In ROS: subscribes ``shared_obstacle_list`` (the handler's latched SharedObstacleArray) and the
map (``~map_topic``, for the grid the master-control areas are drawn on), optionally ``vda5050_order``
(std_msgs/String: a VDA 5050 order as JSON, for systems whose orders come from ROS); publishes
``from_fleet`` (SharedObstacle, source ``master_control``: an external obstacle to the handler,
as the Coaty bridge delivers a peer's) and ``/diagnostics`` (the counters).

The broker: ``~broker_url_param`` (a parameter holding ``mqtt://host:port``, as run_broker sets it; waited for
up to ``~broker_wait`` s) or ``~broker_host``/``~broker_port``; on the fleet's secure broker the login
``~username`` (default: the serial number) with ``~password_file``, and ``~tls_ca``/``~tls_cert``/``~tls_key``
for mqtts (issue 43, item 7)."""
import threading
import time
import urllib.parse

import rospy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from nav_msgs.msg import OccupancyGrid
from sharing_msgs.msg import SharedObstacle, SharedObstacleArray
from std_msgs.msg import String

from vda5050_bridge import core
from vda5050_bridge.client import VdaMqttClient


#: s after start-up before a missing broker or handler list is first warned about, and between repeats
FIRST_WARN_AFTER = 5.0
WARN_INTERVAL = 30.0


class Node:
    def __init__(self):
        ns = rospy.get_namespace().strip("/")
        if not ns and not rospy.has_param("~robot_name"):
            # The handler and the layer live in the robot's namespace: from the root, this node reads a list
            # nobody publishes and sends master control's areas to a from_fleet nobody reads.
            rospy.logwarn("vda5050_bridge runs in the root namespace as robot 'robot': it reads /shared_obstacle_list "
                          "and publishes /from_fleet, which a robot's sharing_handler has in its own namespace. Start it "
                          "beside the handler: ROS_NAMESPACE=robot_0 rosrun vda5050_bridge vda5050_bridge (or "
                          "__ns:=robot_0 in a launch group), or set ~robot_name if this robot has no namespace")
        self.robot = rospy.get_param("~robot_name", ns.replace("/", "_") or "robot")
        if rospy.has_param("~password_file") and not rospy.has_param("~username"):
            rospy.set_param("~username", rospy.get_param("~serial_number", self.robot))   # the vehicle's login
        version = rospy.get_param("~protocol_version", "2.1.0")
        self.bridge = core.BridgeCore(
            version, rospy.get_param("~manufacturer", "fleet"), rospy.get_param("~serial_number", self.robot),
            half_width=float(rospy.get_param("~half_width", 0.3)),
            limits=core.Limits(max_payload_bytes=int(rospy.get_param("~max_payload_bytes", 1048576)),
                               max_zones=int(rospy.get_param("~max_zones", 1000)),
                               max_extent=float(rospy.get_param("~max_zone_extent", 100.0))))
        self.zone_deadline = int(rospy.get_param("~zone_deadline", 3600))
        self.lock = threading.Lock()
        self.grid = None           # (frame_id, resolution, origin_x, origin_y, size_x, size_y)
        self.published = {}        # uuid -> (version, cells, rect) held by the handler from us
        self.pending = {}
        self.pub = rospy.Publisher("from_fleet", SharedObstacle, queue_size=100,
                                   subscriber_listener=_Resend(self))
        self.diag = rospy.Publisher("/diagnostics", DiagnosticArray, queue_size=2)
        host, port, tls = broker_address()
        self.client = VdaMqttClient(
            self.bridge, host, port, interface_name=rospy.get_param("~interface_name", "uagv"), on_areas=self.on_areas,
            log=lambda level, line: (rospy.logerr if level >= 40 else rospy.logwarn)(line),
            username=rospy.get_param("~username", ""), password_file=rospy.get_param("~password_file", ""),
            tls_ca=rospy.get_param("~tls_ca", ""), tls_cert=rospy.get_param("~tls_cert", ""),
            tls_key=rospy.get_param("~tls_key", ""), tls=tls)
        self.started = time.monotonic()
        self.warned = {}           # what was warned about ("broker", "list") -> time.monotonic() of the last warning
        self.list_sub = rospy.Subscriber("shared_obstacle_list", SharedObstacleArray, self.on_list, queue_size=1)
        rospy.Subscriber(rospy.get_param("~map_topic", "/map"), OccupancyGrid, self.on_map, queue_size=1)
        rospy.Subscriber("vda5050_order", String, self.on_order, queue_size=10)
        self.client.start()
        rospy.Timer(rospy.Duration(float(rospy.get_param("~state_interval", 10.0))),
                    lambda _e: self.client.publish_state())
        rospy.Timer(rospy.Duration(1.0), self.on_diagnostics)
        rospy.on_shutdown(self.client.stop)
        rospy.loginfo("%s: vda5050_bridge up: VDA 5050 %s on %s", self.robot, version, self.client.prefix)

    def on_list(self, array):
        obstacles = []
        for o in array.obstacles:
            r = list(o.rectangle_shape)
            if len(r) == 4:
                obstacles.append(core.Obstacle(o.uuid, o.source, tuple(float(v) for v in r)))
        self.client.set_obstacles(obstacles)

    def on_order(self, msg):
        with self.client.lock:
            line = self.bridge.on_message("order", msg.data.encode("utf-8"))
        if line:
            rospy.logwarn("%s: vda5050_order: %s", self.robot, line)
        else:
            self.client.publish_state()

    def on_map(self, grid):
        info = grid.info
        with self.lock:
            self.grid = (grid.header.frame_id or "map", info.resolution, info.origin.position.x,
                         info.origin.position.y, info.width, info.height)
            pending, self.pending = self.pending, {}
        if pending:
            self.on_areas(pending)

    def on_areas(self, areas):
        """Master control's blocked areas now: new ones are sent to the handler as external obstacles,
        withdrawn ones as an update clearing all their cells (the fleet's rule for an obstacle whose
        every cell was seen free)."""
        with self.lock:
            if self.grid is None:
                self.pending = dict(areas)
                rospy.logwarn_throttle(10, "%s: no map yet on ~map_topic; master-control areas wait" % self.robot)
                return
            frame, res, ox, oy, sx, sy = self.grid
            out = []
            for uuid, area in areas.items():
                if uuid not in self.published:
                    cells = core.cells_in_polygon(area.polygon, res, ox, oy, sx, sy)
                    if not cells:
                        rospy.logwarn("%s: master-control area %s lies outside the map" % (self.robot, area.key))
                        continue
                    self.published[uuid] = (1, cells, area.rect)
                    out.append((uuid, 1, cells, [], area.rect))
            for uuid in [u for u in self.published if u not in areas]:
                version, cells, rect = self.published.pop(uuid)
                out.append((uuid, version + 1, [], cells, rect))
        self._send(out, frame, res, ox, oy, sx, sy)

    def resend(self, publish):
        """A (re)started subscriber of from_fleet (a handler) gets every area held now: from_fleet
        is not latched, and a message published before the connection is up is lost."""
        with self.lock:
            if self.grid is None or not self.published:
                return
            frame, res, ox, oy, sx, sy = self.grid
            out = [(uuid, version, cells, [], rect) for uuid, (version, cells, rect) in self.published.items()]
        self._send(out, frame, res, ox, oy, sx, sy, publish)

    def _send(self, out, frame, res, ox, oy, sx, sy, publish=None):
        for uuid, version, marked, cleared, rect in out:
            msg = SharedObstacle()
            msg.header.stamp = rospy.Time.now()
            msg.header.frame_id = frame
            msg.uuid, msg.version, msg.source = uuid, version, core.MASTER_SOURCE
            msg.marked_indexes, msg.cleared_indexes = marked, cleared
            msg.deadline = self.zone_deadline
            msg.rectangle_shape = list(rect)
            msg.resolution, msg.origin_x, msg.origin_y, msg.size_x, msg.size_y = res, ox, oy, sx, sy
            (publish or self.pub.publish)(msg)

    def _due(self, what, now):
        last = self.warned.get(what)
        due = now - self.started >= FIRST_WARN_AFTER if last is None else now - last >= WARN_INTERVAL
        if due:
            self.warned[what] = now
        return due

    def check_links(self):
        """Warns (first after FIRST_WARN_AFTER s, then every WARN_INTERVAL s) while the broker cannot be reached
        or nothing publishes the handler's list: either way master control and this robot hear nothing of
        each other, and the node would otherwise stay silent."""
        now = time.monotonic()
        if not self.client.connected.is_set() and self._due("broker", now):
            rospy.logwarn("%s: vda5050_bridge: VDA 5050 broker %s:%d not reachable for %.0f s: master control gets no "
                          "state from this robot and none of its blocked areas; retrying. Set ~broker_url_param (or "
                          "~broker_host and ~broker_port) to master control's broker", self.robot, self.client.host,
                          self.client.port, now - self.started)
        if self.list_sub.get_num_connections() == 0 and self._due("list", now):
            rospy.logwarn("%s: vda5050_bridge: nothing publishes %s for %.0f s: no fleet obstacle reaches master "
                          "control. Is this robot's sharing_handler running in %s?", self.robot,
                          self.list_sub.resolved_name, now - self.started, rospy.get_namespace())

    def on_diagnostics(self, _event):
        self.check_links()
        with self.client.lock:
            counters = dict(self.bridge.counters)
        connected = self.client.connected.is_set()
        status = DiagnosticStatus(name="vda5050_bridge: %s" % self.robot, hardware_id=self.client.prefix,
                                  level=DiagnosticStatus.OK if connected else DiagnosticStatus.WARN,
                                  message="connected" if connected else "not connected")
        if not connected and self.client.tls_problem:
            status.level = DiagnosticStatus.ERROR
            status.message = "not connected: " + self.client.tls_problem
        status.values = [KeyValue(key=k, value=str(v)) for k, v in sorted(counters.items())]
        array = DiagnosticArray(status=[status])
        array.header.stamp = rospy.Time.now()
        self.diag.publish(array)


class _Resend(rospy.SubscribeListener):
    def __init__(self, node):
        rospy.SubscribeListener.__init__(self)
        self.node = node

    def peer_subscribe(self, _topic, _publish_all, publish_single):
        self.node.resend(publish_single)


def broker_address():
    """(host, port, tls) from ~broker_url_param (waited for, as run_broker sets it) or ~broker_host/~broker_port."""
    name = rospy.get_param("~broker_url_param", "")
    if not name:
        return rospy.get_param("~broker_host", "127.0.0.1"), int(rospy.get_param("~broker_port", 1883)), False
    deadline = rospy.get_time() + float(rospy.get_param("~broker_wait", 30.0))
    while not rospy.has_param(name) and not rospy.is_shutdown():
        if rospy.get_time() > deadline:
            raise ValueError("parameter broker_url_param = %r: not set within ~broker_wait s (is run_broker running?)"
                             % name)
        rospy.sleep(0.1)
    url = urllib.parse.urlsplit(rospy.get_param(name))
    if url.scheme not in ("mqtt", "tcp", "mqtts", "ssl", "tls") or not url.hostname:
        raise ValueError("parameter %s = %r: not mqtt://host:port or mqtts://host:port" % (name, rospy.get_param(name)))
    tls = url.scheme in ("mqtts", "ssl", "tls")
    return url.hostname, url.port or (8883 if tls else 1883), tls


def main():
    rospy.init_node("vda5050_bridge")
    try:
        node = Node()
    except ValueError as err:
        rospy.logfatal("vda5050_bridge: bad parameter: %s", err)
        raise SystemExit(2)
    rospy.loginfo("%s: vda5050_bridge running", node.robot)
    rospy.spin()
