"""rospy node around the SharingHandler: message -> validated value -> logic -> message.

Runs as robot_N/sharing_handler; every topic and service name is relative to the robot
namespace except /diagnostics and the map topic. See the package README for the interface.
"""
import collections
import logging
import sys
import threading
import time

import rospy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from nav_msgs.msg import OccupancyGrid
from sharing_msgs.msg import SharedObstacle, SharedObstacleArray
from sharing_msgs import publisher_links, safe_publisher
from sharing_msgs.authority import FairQueue
from sharing_msgs.safe_publisher import SafePublisher, node_shutting_down
from sharing_msgs.srv import (AddObstacle, AddObstacleResponse, ListObstacles, ListObstaclesResponse, RemoveObstacle,
                              RemoveObstacleResponse)
from std_msgs.msg import String
from visualization_msgs.msg import MarkerArray

from sharing_handler_py import snapshot
from sharing_handler_py.markers import obstacle_markers
from sharing_handler_py.errors import InvalidMessageError, InvalidParameterError, InvalidRequestError
from sharing_handler_py.logic import SharingHandler, remaining_deadline
from sharing_handler_py.validation import Geometry, HandlerParams, Obstacle, Rectangle


#: updates to the fleet kept while no bridge listens (the oldest go first beyond)
UNSENT_KEPT = 1000


class _OnNewSubscriber(rospy.SubscribeListener):
    """Calls ``callback(publish_single)`` whenever a subscriber connects to the publisher."""

    def __init__(self, callback):
        rospy.SubscribeListener.__init__(self)
        self.callback = callback

    def peer_subscribe(self, _topic, _publish_all, publish_single):
        self.callback(publish_single)


class RosoutHandler(logging.Handler):
    """Sends the pure modules' `logging` records to rosout at the matching level."""

    _BY_LEVEL = ((logging.ERROR, rospy.logerr), (logging.WARNING, rospy.logwarn),
                 (logging.INFO, rospy.loginfo), (logging.NOTSET, rospy.logdebug))

    def emit(self, record):
        try:
            text = self.format(record)
            for level, log in self._BY_LEVEL:
                if record.levelno >= level:
                    log(text)
                    return
        except Exception:  # noqa: BLE001 - a log line must never take the node down
            self.handleError(record)


def obstacle_from_msg(msg):
    """SharedObstacle -> Obstacle; raises InvalidMessageError naming what is wrong."""
    geometry = Geometry(float(msg.resolution), float(msg.origin_x), float(msg.origin_y),
                        int(msg.size_x), int(msg.size_y))
    return Obstacle(uuid=msg.uuid, marked=tuple(msg.marked_indexes),
                    cleared=tuple(msg.cleared_indexes), deadline=int(msg.deadline),
                    rectangle=Rectangle.from_sequence(msg.rectangle_shape), source=msg.source,
                    geometry=geometry, version=int(msg.version), frame_id=msg.header.frame_id,
                    stamp=msg.header.stamp.to_sec())


def msg_from_obstacle(obstacle, stamp=None):
    """Obstacle -> SharedObstacle (header stamp = the obstacle's, or `stamp` when given)."""
    msg = SharedObstacle()
    msg.header.frame_id = obstacle.frame_id
    msg.header.stamp = stamp if stamp is not None else rospy.Time.from_sec(max(0.0, obstacle.stamp))
    msg.uuid = obstacle.uuid
    msg.marked_indexes = list(obstacle.marked)
    msg.cleared_indexes = list(obstacle.cleared)
    msg.deadline = obstacle.deadline
    msg.rectangle_shape = obstacle.rectangle.as_list()
    msg.source = obstacle.source
    g = obstacle.geometry
    msg.resolution, msg.origin_x, msg.origin_y = g.resolution, g.origin_x, g.origin_y
    msg.size_x, msg.size_y = g.size_x, g.size_y
    msg.version = obstacle.version
    return msg


def geometry_from_map(grid):
    """OccupancyGrid -> Geometry; raises InvalidMessageError for an unusable map."""
    q = grid.info.origin.orientation
    if abs(q.x) > 1e-6 or abs(q.y) > 1e-6 or abs(q.z) > 1e-6:
        raise InvalidMessageError("bad_geometry", "map origin is rotated (quaternion %.3g %.3g %.3g "
                                  "%.3g); cell indexes assume an axis-aligned grid" % (q.x, q.y, q.z, q.w))
    return Geometry(float(grid.info.resolution), float(grid.info.origin.position.x),
                    float(grid.info.origin.position.y), int(grid.info.width), int(grid.info.height))


def read_params():
    """Reads and checks the private parameters; raises InvalidParameterError."""
    default_name = rospy.get_namespace().strip("/").replace("/", "_")
    return HandlerParams(
        robot_name=rospy.get_param("~robot_name", default_name),
        obstacle_duration=rospy.get_param("~obstacle_duration", 1200.0),
        expiry_rate=rospy.get_param("~expiry_rate", 1.0),
        snapshot_file=rospy.get_param("~snapshot_file", ""),
        max_cells_per_message=rospy.get_param("~max_cells_per_message", 100000),
        max_obstacle_extent=rospy.get_param("~max_obstacle_extent", 10.0),
        merge_distance=rospy.get_param("~merge_distance", 0.5),
        map_topic=rospy.get_param("~map_topic", "/map"),
        max_obstacle_cells=rospy.get_param("~max_obstacle_cells", 0),
        max_version_step=rospy.get_param("~max_version_step", 1000000),
        max_clock_skew=rospy.get_param("~max_clock_skew", 5.0),
        max_obstacles_per_source=rospy.get_param("~max_obstacles_per_source", 1000),
        source_update_rate=rospy.get_param("~source_update_rate", 100.0),
        source_update_burst=rospy.get_param("~source_update_burst", 2000),
        list_cost_share=rospy.get_param("~list_cost_share", 0.05),
        max_sensor_reach=rospy.get_param("~max_sensor_reach", 4.0),
        source_queue_size=rospy.get_param("~source_queue_size", 200),
    )


class HandlerNode:
    """Wires one SharingHandler to topics, services, the map and a timer."""

    def __init__(self, params):
        self.params = params
        self._lock = threading.RLock()
        self._changes = 1           # list changes since start (for the snapshot; 1: the empty list)
        # The latched list is the full state, O(obstacles) to build and send: after a list that took
        # d s the next comes no sooner than d / list_cost_share s later (a change meanwhile is
        # published then, by a timer), so with 10,000 obstacles held an update still costs the same.
        self._list_due = 0.0        # time.monotonic() before which no list is built
        self._list_timer = None     # pending trailing publication
        self._source_reported = {}  # per-source quota counters at the last diagnostics
        self._snapshot_written = -1
        self._dropped_reported = 0
        self._map_frame = ""
        self._list_cache = {}       # uuid -> (cells, metadata, SharedObstacle) of the last list
        # Fleet messages wait in a queue per source, served round-robin by one worker (issue 43, item 5): a
        # login flooding valid obstacles fills only its own queue, and another robot's message waits for at
        # most one of its messages, not for the flood (rospy's own queue drops the oldest, whoever sent it).
        self._fleet_inbox = FairQueue(params.source_queue_size)
        # Built before any publisher: a subscriber may connect while a publisher registers (the layer of a move_base
        # started first, a bench's probe), and its listener hands it what the handler holds. Built after them, that
        # subscriber's connection failed ("no attribute 'handler'") and it never got an obstacle.
        self.handler = SharingHandler(
            params.robot_name, lambda: rospy.get_time(), params.obstacle_duration,
            on_to_layer=lambda o: self._deliver(self._pub_layer, o),
            on_to_fleet=self._to_fleet,
            on_expired=lambda u: self._pub_expired.publish(String(data=u)),
            on_change=self._list_changed,
            max_cells_per_message=params.max_cells_per_message,
            max_obstacle_extent=params.max_obstacle_extent,
            merge_distance=params.merge_distance,
            max_obstacle_cells=params.max_obstacle_cells,
            max_version_step=params.max_version_step,
            max_clock_skew=params.clock_skew,
            max_obstacles_per_source=params.max_obstacles_per_source,
            source_update_rate=params.source_update_rate,
            source_update_burst=params.source_update_burst,
            max_sensor_reach=params.max_sensor_reach)
        # One message that cannot be serialised is dropped there; the publisher stays usable.
        self._pub_layer = SafePublisher(
            lambda: rospy.Publisher("shared_obstacles", SharedObstacle, queue_size=100,
                                    subscriber_listener=_OnNewSubscriber(self._on_new_layer)),
            topic="%s/shared_obstacles" % params.robot_name,
            shutting_down=node_shutting_down)
        self._pub_expired = rospy.Publisher("expired_obstacles", String, queue_size=100)
        # What goes to the fleet while no bridge listens (it crashed and is starting again: issue 43, item 8) is kept,
        # and handed to the bridge when it subscribes, deadlines aged: nothing this robot shares is lost that way.
        self._unsent = collections.deque(maxlen=UNSENT_KEPT)   # (Obstacle, clock time)
        self._pub_fleet = SafePublisher(
            lambda: rospy.Publisher("to_fleet", SharedObstacle, queue_size=1000,
                                    subscriber_listener=_OnNewSubscriber(self._on_new_bridge)),
            topic="%s/to_fleet" % params.robot_name,
            shutting_down=node_shutting_down)
        self._pub_list = rospy.Publisher("shared_obstacle_list", SharedObstacleArray, queue_size=1,
                                         latch=True)
        self._pub_diag = rospy.Publisher("/diagnostics", DiagnosticArray, queue_size=10)
        # RViz: the fleet's obstacles with source, age, time left and cells (markers.py), on every change and
        # at each tick (the ages move), only while someone looks. Not latched: a subscriber gets the markers of the
        # obstacles held when it connects, built then; a latched array would have to be built and serialised on every
        # change of the list whether or not anyone looks, under the lock (1,200 obstacles held: ~40 ms of CPU each
        # time, which a flooding login's obstacles made other robots' messages wait for).
        self._pub_markers = rospy.Publisher("fleet_obstacle_markers", MarkerArray, queue_size=1,
                                            subscriber_listener=_OnNewSubscriber(self._on_new_markers_subscriber))
        self._publish_list()  # an empty latched list, so late joiners see "nothing" not silence
        rospy.Subscriber(params.map_topic, OccupancyGrid, self._on_map, queue_size=1)
        rospy.Subscriber("obstacle_proposals", SharedObstacle, self._on_proposal, queue_size=100)
        rospy.Subscriber("obstacle_updates", SharedObstacle, self._on_update, queue_size=1000)
        rospy.Subscriber("from_fleet", SharedObstacle, self._on_fleet, queue_size=1000)
        # copies restoring state (the bridge's Discover answers, its copy for a restarted handler): never renewals
        rospy.Subscriber("fleet_state", SharedObstacle, self._on_fleet_state, queue_size=1000)
        rospy.Service("list_obstacles", ListObstacles, self._on_list)
        rospy.Service("add_obstacle", AddObstacle, self._on_add)
        rospy.Service("remove_obstacle", RemoveObstacle, self._on_remove)
        self._timer = rospy.Timer(rospy.Duration(1.0 / params.expiry_rate), self._on_tick)
        rospy.loginfo("%s: sharing handler up (obstacle_duration %g s, merge_distance %g m, expiry %g Hz, "
                      "map %s, snapshot %s)", params.robot_name, params.obstacle_duration,
                      params.merge_distance, params.expiry_rate, params.map_topic,
                      params.snapshot_file or "off")
        if params.clock_skew is None:
            rospy.logwarn("%s: max_clock_skew = -1: stamps of fleet messages are not checked, so a replayed "
                          "message is refused only while its uuid is remembered as expired", params.robot_name)

    def _to_fleet(self, obstacle):
        if self._pub_fleet.get_num_connections() == 0:
            self._unsent.append((obstacle, rospy.get_time()))
            return
        self._deliver(self._pub_fleet, obstacle)

    def _on_new_bridge(self, publish_single):
        """A bridge subscribed to to_fleet: what this robot shared while none listened goes to it now, oldest first."""
        with self._lock:
            unsent, now = list(self._unsent), rospy.get_time()
            self._unsent.clear()
        sent = 0
        for obstacle, made in unsent:
            left = obstacle.deadline - max(0.0, now - made)
            if left < 1.0:
                continue   # it ended meanwhile on this robot: sending it would revive it elsewhere
            try:
                publish_single(msg_from_obstacle(obstacle.replace(deadline=int(left))))
                sent += 1
            except Exception as err:  # noqa: BLE001 - one bad value must not stop the rest
                rospy.logwarn("%s: obstacle %s not handed to the bridge: %s", self.params.robot_name, obstacle.uuid, err)
        if sent:
            rospy.loginfo("%s: a bridge subscribed: handed it the %d updates made while none listened",
                          self.params.robot_name, sent)

    def _on_new_layer(self, publish_single):
        """A layer subscribed (move_base started, or started again after a crash: issue 43, item 8): it gets every
        obstacle held here, full state, on its own connection."""
        with self._lock:
            held = self.handler.obstacles()
        for h in held:
            try:
                publish_single(msg_from_obstacle(h.to_obstacle()))
            except Exception as err:  # noqa: BLE001 - one bad value must not stop the rest
                rospy.logwarn("%s: obstacle %s not handed to a new layer: %s", self.params.robot_name, h.uuid, err)
        if held:
            rospy.loginfo("%s: a layer subscribed: handed it the %d obstacles held", self.params.robot_name, len(held))

    def _deliver(self, publisher, obstacle):
        try:
            msg = msg_from_obstacle(obstacle)
        except Exception as err:  # noqa: BLE001 - one bad value must not stop the node
            publisher.drop("conversion", "%s: obstacle %s v%d from %s" % (
                self.params.robot_name, obstacle.uuid, obstacle.version, obstacle.source), err)
            return
        publisher.publish(msg, "%s: obstacle %s v%d from %s" % (
            self.params.robot_name, obstacle.uuid, obstacle.version, obstacle.source))

    # ------------------------------------------------------------ callbacks

    def _convert(self, msg, topic):
        try:
            return obstacle_from_msg(msg)
        except InvalidMessageError as err:
            with self._lock:
                self.handler.reject("%s (on %s)" % (msg.source or "?", topic), msg.uuid, err)
            return None

    def _on_proposal(self, msg):
        obstacle = self._convert(msg, "obstacle_proposals")
        if obstacle is not None:
            with self._lock:
                self.handler.on_proposal(obstacle)

    def _on_update(self, msg):
        obstacle = self._convert(msg, "obstacle_updates")
        if obstacle is not None:
            with self._lock:
                self.handler.on_internal_update(obstacle)

    def _on_fleet(self, msg):
        self._queue_fleet(msg, "from_fleet", True)

    def _on_fleet_state(self, msg):
        self._queue_fleet(msg, "fleet_state", False)

    def _queue_fleet(self, msg, topic, live):
        """rospy's thread: only sorts the message behind its source (fair delivery); the worker converts and applies.

        This thread reads one connection per publisher in arrival order: whatever it does per message, a flood's
        messages ahead of another robot's are done first. Converting here (validating every cell index) put a
        flooding login's whole backlog in front of the honest robot's message (bench_flood: 0.6 s at p99 in this
        handler alone), so conversion waits in the source's queue like the rest of the work."""
        if not self._fleet_inbox.put(msg.source, (msg, topic, live)):
            with self._lock:
                self.handler.queue_full(msg)      # counted and named per source: uuid, version, source suffice

    def serve_fleet(self, stop):
        """The worker: converts and applies queued fleet messages, one source at a time in turn, until ``stop``."""
        while not stop.is_set():
            if self.serve_one(timeout=0.5):
                # give rospy's reading thread the GIL now, not after the 5 ms switch interval: while this worker
                # is busy with a flood it would otherwise read about one message per 5 ms, and another robot's
                # message would sit unsorted behind the flood's in the socket
                time.sleep(0)

    def serve_one(self, timeout=None):
        """Converts and applies the next queued fleet message (round-robin over sources); False when none came
        within ``timeout`` s."""
        item = self._fleet_inbox.get(timeout=timeout)
        if item is None:
            return False
        msg, topic, live = item[1]
        obstacle = self._convert(msg, topic)
        if obstacle is None:
            return True
        with self._lock:
            if live:
                self.handler.on_external(obstacle)
            else:
                self.handler.on_state(obstacle)
        return True

    def _on_map(self, grid):
        try:
            geometry = geometry_from_map(grid)
        except InvalidMessageError as err:
            rospy.logerr("%s: ignoring map on %s: %s", self.params.robot_name, self.params.map_topic, err)
            return
        with self._lock:
            self._map_frame = grid.header.frame_id
            if self.handler.geometry is None or not self.handler.geometry.matches(geometry):
                rospy.loginfo("%s: grid from %s: %s", self.params.robot_name, self.params.map_topic,
                              geometry)
                self.handler.set_geometry(geometry)

    def _on_list(self, _request):
        with self._lock:
            held = self.handler.obstacles()
        response = ListObstaclesResponse()
        response.obstacles = [msg_from_obstacle(h.to_obstacle(), rospy.Time.now()) for h in held]
        response.arrival_times = [h.arrival for h in held]
        response.remaining_seconds = [h.remaining for h in held]
        return response

    def _on_add(self, request):
        try:
            with self._lock:
                shared = self.handler.add_manual(list(request.rectangle_shape),
                                                 tuple(request.marked_indexes), request.deadline,
                                                 frame_id=self._map_frame)
        except InvalidRequestError as err:
            rospy.logwarn("%s: add_obstacle refused: %s", self.params.robot_name, err)
            return AddObstacleResponse(success=False, message=str(err), uuid="")
        return AddObstacleResponse(success=True, message="shared", uuid=shared.uuid)

    def _on_remove(self, request):
        try:
            with self._lock:
                removed = self.handler.remove(uuid=request.uuid or None,
                                              rectangle=None if request.uuid else list(request.rectangle_shape),
                                              requested_by=request.requested_by)
        except InvalidRequestError as err:
            rospy.logwarn("%s: remove_obstacle (requested by %r) refused: %s", self.params.robot_name,
                          request.requested_by[:80], err)
            return RemoveObstacleResponse(success=False, message=str(err), removed=[])
        return RemoveObstacleResponse(success=True, message="removed fleet-wide: %s" % ", ".join(removed),
                                      removed=removed)

    def _on_tick(self, _event):
        with self._lock:
            self.handler.expire()
            self._publish_diagnostics()
            self._publish_markers()
            if self.params.snapshot_file and self._snapshot_written != self._changes:
                self._write_snapshot()

    # ------------------------------------------------------------ outputs

    def _list_changed(self):
        """The handler's list changed (called with the lock held): publish now, or once the list's
        cost share allows (a timer; every change is in the list published then)."""
        self._changes += 1
        wait = self._list_due - time.monotonic()
        if wait <= 0:
            self._publish_list()
        elif self._list_timer is None:
            self._list_timer = threading.Timer(wait, self._publish_pending_list)
            self._list_timer.daemon = True
            self._list_timer.start()

    def _publish_pending_list(self):
        with self._lock:
            self._list_timer = None
            if not rospy.is_shutdown():
                self._publish_list()

    def _publish_list(self):
        started = time.monotonic()
        now = rospy.Time.now()
        array = SharedObstacleArray()
        array.header.stamp = now
        array.header.frame_id = self._map_frame
        fresh = {}
        array.obstacles = [self._list_entry(h, now, fresh) for h in self.handler.obstacles()]
        self._list_cache = fresh
        self._pub_list.publish(array)
        self._publish_markers()
        finished = time.monotonic()
        self._list_due = finished + (finished - started) / self.params.list_cost_share

    def _publish_markers(self):
        """On every change of the list and at each tick (the labels' ages move), only while someone looks; a
        subscriber that connects gets the current markers first (_on_new_markers_subscriber)."""
        if self._pub_markers.get_num_connections() == 0:
            return
        self._pub_markers.publish(self._markers())

    def _markers(self):
        return obstacle_markers(self.handler.obstacles(), rospy.get_time(), self._map_frame or "map", rospy.Time.now())

    def _on_new_markers_subscriber(self, publish_single):
        """RViz (or rostopic echo) connected: the obstacles held now, on its own connection."""
        with self._lock:
            markers = self._markers()
        try:
            publish_single(markers)
        except Exception as err:  # noqa: BLE001 - a closed connection must not disturb the rest
            rospy.logwarn("%s: markers not sent to a new subscriber: %s", self.params.robot_name, err)

    def _list_entry(self, held, now, fresh):
        """Full-state message of one held obstacle. The message built for the last list is
        reused while the obstacle's cells and metadata are the same objects/values (publish()
        serialises at once, so updating the reused message afterwards is safe)."""
        key = (held.version, held.source, held.rectangle, held.frame_id)
        cached = self._list_cache.get(held.uuid)
        if cached is None or cached[0] is not held.cells or cached[1] != key:
            cached = (held.cells, key, msg_from_obstacle(held.to_obstacle(), now))
        fresh[held.uuid] = cached
        msg = cached[2]
        msg.header.stamp = now
        msg.deadline = remaining_deadline(held.remaining)  # aged to header.stamp, rounded down
        return msg

    def _publish_diagnostics(self):
        counters = self.handler.counters
        dropped = sum(v for k, v in counters.items() if k.startswith("dropped_"))
        status = DiagnosticStatus(name="sharing_handler (%s)" % self.params.robot_name,
                                  hardware_id=self.params.robot_name)
        delivery, worst, problems = {}, safe_publisher.OK, []
        for topic, publisher in (("shared_obstacles", self._pub_layer), ("to_fleet", self._pub_fleet)):
            level, problem, errors = publisher.report()
            worst = max(worst, level)
            problems += [problem] if problem else []
            for reason, n in errors.items():
                delivery["delivery_error.%s.%s" % (topic, reason)] = n
        if worst == safe_publisher.ERROR:
            status.level = DiagnosticStatus.ERROR
            status.message = "; ".join(problems)
        elif worst == safe_publisher.WARN:
            status.level = DiagnosticStatus.WARN
            status.message = "; ".join(problems)
        elif dropped > self._dropped_reported:
            status.level = DiagnosticStatus.WARN
            status.message = "%d messages dropped since the last report" % (dropped - self._dropped_reported)
        else:
            status.level = DiagnosticStatus.OK
            status.message = "%d obstacles held" % len(self.handler)
        self._dropped_reported = dropped
        per_source = self.handler.source_counters()
        new = sorted(((n - self._source_reported.get(k, 0), k) for k, n in per_source.items()
                      if n > self._source_reported.get(k, 0)), reverse=True)
        self._source_reported = per_source
        if new and status.level != DiagnosticStatus.ERROR:
            # who floods, and which limit: e.g. "robot_9: 3994 dropped_source_quota"
            status.level = DiagnosticStatus.WARN
            status.message += "; quota: " + ", ".join("%s: %d %s" % (k.split(".", 1)[1], n, k.split(".", 1)[0])
                                                     for n, k in new[:3])
        status.values = [KeyValue(key="obstacles", value=str(len(self.handler))),
                         KeyValue(key="grid", value=str(self.handler.geometry or "unknown")),
                         KeyValue(key="dropped", value=str(dropped))]
        status.values += [KeyValue(key=k, value=str(v)) for k, v in sorted(counters.items())]
        status.values += [KeyValue(key=k, value=str(v)) for k, v in sorted(per_source.items())]
        status.values += [KeyValue(key=k, value=str(v)) for k, v in sorted(delivery.items())]
        array = DiagnosticArray(status=[status])
        array.header.stamp = rospy.Time.now()
        self._pub_diag.publish(array)

    def _write_snapshot(self):
        try:
            text = snapshot.render(self.params.robot_name, rospy.get_time(), self.handler.obstacles())
            snapshot.write_atomically(self.params.snapshot_file, text)
            self._snapshot_written = self._changes
        except (OSError, ValueError) as err:
            rospy.logwarn_throttle(30, "%s: cannot write snapshot %s: %s" % (
                self.params.robot_name, self.params.snapshot_file, err))


def main(argv=None):
    rospy.init_node("sharing_handler", argv=argv)
    for name in ("sharing_handler_py", "sharing_msgs"):  # sharing_msgs: the safe publishers' drops
        log = logging.getLogger(name)
        log.setLevel(logging.DEBUG)  # rospy's own level decides what is shown
        log.addHandler(RosoutHandler())
        log.propagate = False
    try:
        params = read_params()
    except InvalidParameterError as err:
        message = "sharing_handler: bad parameter %s" % err
        rospy.logfatal(message)
        print(message, file=sys.stderr)
        sys.exit(2)
    node = HandlerNode(params)
    stop = threading.Event()
    rospy.on_shutdown(stop.set)
    threading.Thread(target=node.serve_fleet, args=(stop,), name="sharing_handler fleet inbox", daemon=True).start()
    publisher_links.start_watch(rospy.get_name())
    rospy.spin()
