"""rospy node ``coaty_bridge``: wires the robot's topics to one Coaty agent.

    to_fleet (SharedObstacle)               -> Advertise to the fleet
    fleet (Advertise, renewals)             -> from_fleet (SharedObstacle): observations
    fleet (Resolve to our Discover)         -> fleet_state (SharedObstacle): copies restoring state
    shared_obstacle_list (SharedObstacleArray, latched) -> answers to obstacle Discovers
    move_base/global_costmap/footprint (PolygonStamped) -> Advertise of this robot's footprint, 2 Hz
    fleet (footprint Advertise)             -> fleet_robots (RobotFootprintArray, latched, 2 Hz)
    /diagnostics                            <- counters, once a second
"""
import dataclasses
import logging
import os
import sys
import threading

import rospy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point32, PolygonStamped
from sharing_msgs.msg import RobotFootprint, RobotFootprintArray, SharedObstacle, SharedObstacleArray
from sharing_msgs import publisher_links, safe_publisher
from sharing_msgs.authority import MASTER_CONTROL
from sharing_msgs.safe_publisher import SafePublisher, node_shutting_down

from coaty_bridge.client import BridgeConfig, CoatyBridgeClient, choose_broker_url
from coaty_bridge.connection import masked_client_id
from coaty_bridge import liveness
from coaty_bridge.codec import ObstacleUpdate
from coaty_bridge.errors import CoatyError
from coaty_bridge.security import read_password_file
from coaty_bridge.footprint import FleetRobotTable, near_any, RobotFootprint as FootprintValue, centroid
from coaty_bridge.footprint_config import FootprintConfig

LOG = logging.getLogger(__name__)

#: per-sender drop counters named in /diagnostics as they rise: floods (issue 27) and implausible evidence (issue 43)
SENDER_DROPS = ("dropped_source_rate_limited.", "dropped_source_queue_full.", "dropped_implausible_cells.",
                "dropped_implausible_evidence.")

# private parameter -> BridgeConfig field default; the types are checked by BridgeConfig
_PARAMS = ("broker_url", "namespace", "object_type", "footprint_object_type", "identity_id", "tls_ca", "tls_cert",
           "tls_key", "username", "password", "max_payload_bytes", "max_indexes",
           "offline_queue_size", "max_obstacle_extent", "max_obstacle_cells", "compact_indexes", "keepalive", "reconnect_min_delay",
           "reconnect_max_delay", "discover_window", "discover_answer_rate", "discover_answer_burst", "discover_answers", "authenticate_sources", "footprint_area_size",
           "obstacle_area_size",
           "broker_warn_interval", "max_footprint_extent", "known_robots", "operators", "heartbeat_interval",
           "liveness_timeout", "peer_heartbeat_interval", "insecure", "source_message_rate", "source_message_burst", "source_queue_size",
           "sensor_reach", "max_sensor_reach", "require_evidence", "evidence_window", "max_robot_speed",
           "localisation_tolerance")


def msg_to_update(msg):
    """SharedObstacle -> ObstacleUpdate (ValueError naming the bad field)."""
    return ObstacleUpdate(
        uuid=msg.uuid, source=msg.source, version=int(msg.version),
        stamp=msg.header.stamp.to_sec(), frame_id=msg.header.frame_id, deadline=int(msg.deadline),
        rectangle=tuple(float(v) for v in msg.rectangle_shape), resolution=float(msg.resolution),
        origin_x=float(msg.origin_x), origin_y=float(msg.origin_y),
        size_x=int(msg.size_x), size_y=int(msg.size_y),
        marked=tuple(int(v) for v in msg.marked_indexes),
        cleared=tuple(int(v) for v in msg.cleared_indexes))


def update_to_msg(update):
    """ObstacleUpdate -> SharedObstacle, casting every number to the field's type."""
    msg = SharedObstacle()
    msg.header.stamp = rospy.Time.from_sec(float(update.stamp))
    msg.header.frame_id = update.frame_id
    msg.uuid = update.uuid
    msg.marked_indexes = [int(v) for v in update.marked]
    msg.cleared_indexes = [int(v) for v in update.cleared]
    msg.deadline = int(update.deadline)
    msg.rectangle_shape = [float(v) for v in update.rectangle]
    msg.source = update.source
    msg.resolution = float(update.resolution)
    msg.origin_x = float(update.origin_x)
    msg.origin_y = float(update.origin_y)
    msg.size_x = int(update.size_x)
    msg.size_y = int(update.size_y)
    msg.version = int(update.version)
    return msg


class _OnNewSubscriber(rospy.SubscribeListener):
    """Calls ``callback()`` whenever a subscriber connects to the publisher."""

    def __init__(self, callback):
        rospy.SubscribeListener.__init__(self)
        self.callback = callback

    def peer_subscribe(self, _topic, _publish_all, _publish_single):
        self.callback()


class RosoutHandler(logging.Handler):
    """Sends the pure modules' log records to rosout."""

    def emit(self, record):
        text = self.format(record)
        if record.levelno >= logging.ERROR:
            rospy.logerr(text)
        elif record.levelno >= logging.WARNING:
            rospy.logwarn(text)
        elif record.levelno >= logging.INFO:
            rospy.loginfo(text)
        else:
            rospy.logdebug(text)


def polygon_to_footprint(msg, robot, now):
    """PolygonStamped (this robot's footprint at its pose) -> validated RobotFootprint; a zero stamp
    means now. ValueError (a CoatyError) names the bad field."""
    stamp = msg.header.stamp.to_sec() if not msg.header.stamp.is_zero() else now
    return FootprintValue(robot=robot, stamp=stamp, frame_id=msg.header.frame_id.lstrip("/"),
                          points=tuple((float(p.x), float(p.y)) for p in msg.polygon.points))


def fleet_robots_message(heard, now, timeout):
    """The known fleet robots as a RobotFootprintArray at ``now``: a dead-reckoned advert moved on
    (HeardRobot.points_at); each robot's stamp is when it was heard, kept fresh for an advert's validFor
    (HeardRobot.vouched_at, ``timeout`` the robot_timeout)."""
    array = RobotFootprintArray()
    array.header.stamp = rospy.Time.from_sec(now)
    for item in heard:
        robot = RobotFootprint()
        robot.header.stamp = rospy.Time.from_sec(max(0.0, item.vouched_at(now, timeout)))
        robot.header.frame_id = item.footprint.frame_id
        robot.robot = item.footprint.robot
        robot.footprint.points = [Point32(x, y, 0.0) for x, y in item.points_at(now)]
        array.robots.append(robot)
    return array


#: Hz fleet_robots is published at while a known robot drives on a dead-reckoned advert (ROS only, not the wire)
MOVING_PEERS_RATE = 10.0


def default_robot_name():
    return rospy.get_namespace().strip("/").replace("/", "_")


class RosParams:
    """The parameter server as choose_broker_url sees it (tests pass a dict-backed stand-in)."""

    has = staticmethod(rospy.has_param)
    get = staticmethod(rospy.get_param)
    resolve = staticmethod(rospy.resolve_name)


def read_config():
    """Reads the private parameters into a BridgeConfig and the broker URL's origin; ValueError
    names a bad one. Returns (BridgeConfig, BrokerUrlChoice)."""
    kwargs = {}
    for name in _PARAMS:
        if name != "broker_url" and rospy.has_param("~" + name):
            kwargs[name] = rospy.get_param("~" + name)
    if "operators" not in kwargs and rospy.has_param("/fleet/operators"):
        # the fleet console's operator logins, as the fleet launch's operators:= names them for every robot
        kwargs["operators"] = rospy.get_param("/fleet/operators")
    broker_wait = rospy.get_param("~broker_wait", 30.0)
    choice = choose_broker_url(RosParams, lambda name: wait_for_param(name, broker_wait))
    robot_name = rospy.get_param("~robot_name", "") or default_robot_name()
    if not robot_name:
        raise ValueError("parameter robot_name = '': not set and the node runs in the root "
                         "namespace; run it as robot_N/coaty_bridge or set ~robot_name")
    if choice.warning:
        rospy.logwarn("%s: coaty_bridge: %s", robot_name, choice.warning)
    password_file = rospy.get_param("~password_file", "")
    if password_file:
        # read once the broker is up: run_broker makes the secret on first use before it sets the URL
        if not isinstance(password_file, str):
            raise ValueError("parameter password_file = %r: must be a file name" % (password_file,))
        if kwargs.get("password"):
            raise ValueError("parameter password_file = %r: set either password or password_file" % (password_file,))
        # a URL left on the master by an earlier launch can come before run_broker made the secret
        deadline = rospy.get_time() + (broker_wait if isinstance(broker_wait, (int, float)) else 0)
        while not os.path.exists(password_file) and rospy.get_time() < deadline and not rospy.is_shutdown():
            rospy.sleep(0.1)
        try:
            kwargs["password"] = read_password_file(password_file)
        except ValueError as err:
            raise ValueError("parameter %s" % err) from None
        kwargs["password_file"] = password_file
    try:
        config = BridgeConfig(robot_name=robot_name, broker_url=choice.url, broker_url_source=choice.source,
                              **kwargs)
    except ValueError as err:
        if "broker_url" in str(err).split("=")[0]:
            raise ValueError("%s (from %s)" % (err, choice.source)) from None
        raise
    return config, choice


def wait_for_param(name, timeout):
    """Waits up to ``timeout`` s for a parameter another node (run_broker) sets."""
    if isinstance(timeout, bool) or not isinstance(timeout, (int, float)) or timeout < 0:
        raise ValueError("parameter broker_wait = %r: must be a number of seconds >= 0" % (timeout,))
    deadline = rospy.get_time() + timeout
    while not rospy.is_shutdown():
        if rospy.has_param(name):
            return rospy.get_param(name)
        if rospy.get_time() >= deadline:
            raise ValueError("parameter broker_url_param = %r: not set within %.0f s (is run_broker "
                             "running?)" % (name, timeout))
        rospy.sleep(0.1)
    raise ValueError("shut down while waiting for %s" % name)


class BridgeNode:
    """Callbacks only convert and hand over; the logic lives in CoatyBridgeClient."""

    def __init__(self, config, footprint_config=None):
        self.config = config
        self.footprint_config = footprint_config or FootprintConfig()
        self._lock = threading.Lock()
        self._counters = {}
        self._sender_drops_reported = {}   # per-sender drop counters at the last diagnostics
        self._own_footprint = None   # (RobotFootprint, ROS time it arrived)
        # when to advertise the own footprint
        self._adverts = self.footprint_config.schedule(config.footprint_area_size)
        self._stale_logged = False
        self.fleet = FleetRobotTable(config.robot_name, self.footprint_config.robot_timeout, rospy.get_time)
        # A message that cannot be delivered is dropped there; the publisher stays usable.
        self.from_fleet = SafePublisher(
            lambda: rospy.Publisher("from_fleet", SharedObstacle, queue_size=100),
            topic="%s/from_fleet" % config.robot_name, shutting_down=node_shutting_down)
        # set before the publisher whose listener reads it: a subscriber may connect while a publisher registers
        self._started = False
        # Resolves answering our Discover restore state: the handler never takes them as a renewal (issue 43)
        self.fleet_state = SafePublisher(
            lambda: rospy.Publisher("fleet_state", SharedObstacle, queue_size=1000,
                                    subscriber_listener=_OnNewSubscriber(self._on_restarted_handler)),
            topic="%s/fleet_state" % config.robot_name, shutting_down=node_shutting_down)
        self.diagnostics = rospy.Publisher("/diagnostics", DiagnosticArray, queue_size=10)
        self.client = CoatyBridgeClient(config, self._on_fleet_obstacle, on_footprint=self._on_fleet_footprint,
                                        on_footprint_withdrawn=self._on_fleet_footprint_withdrawn)
        # a robot that advertises its footprint keeps its first obstacles back until its footprint is here
        self.client.expect_footprints(self.footprint_config.advertise)
        self.fleet_robots = rospy.Publisher("fleet_robots", RobotFootprintArray, queue_size=2, latch=True)
        rospy.Subscriber("to_fleet", SharedObstacle, self._on_to_fleet, queue_size=100)
        rospy.Subscriber("shared_obstacle_list", SharedObstacleArray, self._on_obstacle_list, queue_size=2)
        rospy.Subscriber(self.footprint_config.topic, PolygonStamped, self._on_own_footprint, queue_size=10)
        self._timer = rospy.Timer(rospy.Duration(1.0), self._publish_diagnostics)
        self._footprint_timer = rospy.Timer(rospy.Duration(1.0 / self.footprint_config.rate), self._footprint_tick)
        # driving peers' dead-reckoned footprints, moved on for the layer between their adverts
        self._moving_timer = rospy.Timer(rospy.Duration(1.0 / MOVING_PEERS_RATE), self._moving_peers_tick)

    def start(self, subscriber_wait):
        """Connects to the fleet once from_fleet has a subscriber (or after ``subscriber_wait``
        s): the Resolves that answer our start-up Discover arrive within milliseconds, and
        a ROS subscriber that is still connecting would miss them."""
        deadline = rospy.get_time() + subscriber_wait
        while self.from_fleet.get_num_connections() == 0 and rospy.get_time() < deadline \
                and not rospy.is_shutdown():
            rospy.sleep(0.05)
        if self.from_fleet.get_num_connections() == 0:
            rospy.logwarn("%s: nobody subscribes from_fleet after %.1f s; connecting anyway",
                          self.config.robot_name, subscriber_wait)
        rospy.loginfo("%s: coaty_bridge agent %s, broker %s (from %s), namespace %s, objectType %s, "
                      "MQTT client id %s, login %s%s",
                      self.config.robot_name, self.client.identity_id, self.config.broker_url,
                      self.config.broker_url_source, self.config.namespace, self.config.object_type,
                      masked_client_id(self.client.client_id), self.config.username or "anonymous",
                      ", authenticated sources" if self.config.authenticate_sources else "")
        if self.config.insecure:
            rospy.logwarn("%s: coaty_bridge: INSECURE (insecure:=true)%s: %s", self.config.robot_name,
                          "" if self.config.authenticate_sources else ", authenticate_sources off",
                          "obstacles under any robot's name are taken from anyone on the broker, and a broker "
                          "that is not on this machine may be reached without TLS")
        self.client.start()
        self._started = True

    def _on_restarted_handler(self):
        """A new subscriber of fleet_state after start: the handler started again (issue 43, item 8) and holds
        nothing. The fleet is asked again, and this robot's own updates go to it at once."""
        if not self._started:
            return   # the first connect asks the fleet anyway
        def restore():
            rospy.sleep(0.5)   # the subscriber's connection completes after this callback
            own = self.client.restore()
            for update in own:
                try:
                    self.fleet_state.publish(update_to_msg(update), "%s: own obstacle %s v%d back to the handler" % (
                        self.config.robot_name, update.uuid, update.version))
                except Exception as err:  # noqa: BLE001 - one bad value must not stop the rest
                    self.fleet_state.drop("conversion", "own obstacle %s" % update.uuid, err)
            if own:
                rospy.loginfo("%s: %d of this robot's own updates handed back to the handler", self.config.robot_name,
                              len(own))
        threading.Thread(target=restore, name="coaty_bridge restore", daemon=True).start()

    def shutdown(self):
        self._timer.shutdown()
        self._footprint_timer.shutdown()
        self._moving_timer.shutdown()
        self.client.stop()

    def _count(self, key):
        with self._lock:
            self._counters[key] = self._counters.get(key, 0) + 1

    def _on_fleet_obstacle(self, update, topic):
        what = "%s: obstacle %s v%d from %s (sourceId %s)" % (
            self.config.robot_name, update.uuid, update.version, update.source, topic.source_id)
        try:
            msg = update_to_msg(update)
        except Exception as err:  # noqa: BLE001 - one bad value must not stop delivery
            self.from_fleet.drop("conversion", what, err)
            return
        (self.fleet_state if topic.event == "RSV" else self.from_fleet).publish(msg, what)

    def _on_own_footprint(self, msg):
        try:
            footprint = polygon_to_footprint(msg, self.config.robot_name, rospy.get_time())
        except ValueError as err:
            self._count("dropped_own_footprint")
            rospy.logwarn_throttle(5.0, "%s: footprint on %s not advertised: %s" % (
                self.config.robot_name, self.footprint_config.topic, err))
            return
        now = rospy.get_time()
        self._own_footprint = (footprint, now)
        self.client.note_own_position(centroid(footprint.points))
        self.client.note_own_footprint(footprint)   # the evidence before its obstacle messages
        # A peer's layer must not share this robot's front: while it drives, its pose at the peers may lag by
        # at most min_move (plus transport), not by a whole heartbeat period of driving.
        # The schedule runs on the footprint's stamp (when the pose held), not on when it arrived here: the
        # velocity of a dead-reckoned advert is not to swing with the footprint topic's transport delays.
        if self.footprint_config.advertise:
            near = self._near(footprint.points)
            with self._lock:
                valid_for = self._adverts.on_footprint(footprint.points, footprint.stamp, near)
                decision = self._adverts.decision
            if valid_for is not None:
                self._advertise(footprint, footprint.stamp, valid_for, decision)

    def _near(self, points):
        """Whether a known fleet robot is within footprint_near_distance (else this robot's adverts are far ones)."""
        now = rospy.get_time()
        return near_any(points, [r.points_at(now) for r in self.fleet.robots()], self.footprint_config.near_distance)

    def _advertise(self, footprint, at, valid_for, decision):
        """Sends the advert the schedule decided on ``footprint`` (taken ``at``, its stamp)."""
        footprint = dataclasses.replace(footprint, valid_for=valid_for, velocity=decision[1])
        if self.client.publish_footprint(footprint):
            with self._lock:
                self._adverts.sent(footprint.points, at, valid_for, decision)

    def _on_fleet_footprint(self, footprint, topic):
        """MQTT thread: a peer's footprint advert (already validated)."""
        known = footprint.robot in {r.footprint.robot for r in self.fleet.robots()}
        if footprint.robot != self.config.robot_name and not self.fleet.heard(footprint):
            self._count("footprints_out_of_order")
        else:
            if not known and footprint.robot != self.config.robot_name:
                rospy.loginfo("%s: fleet robot %s heard (sourceId %s); its footprint is never shared",
                              self.config.robot_name, footprint.robot, topic.source_id)
            if footprint.robot != self.config.robot_name:
                # At once, not at the next tick: a driving robot's footprint a tick old has moved on.
                self.fleet_robots.publish(fleet_robots_message(self.fleet.robots(), rospy.get_time(),
                                                            self.footprint_config.robot_timeout))

    def _on_fleet_footprint_withdrawn(self, robot, topic):
        """MQTT thread: a peer took its footprint back (stopped, or its navigation went quiet)."""
        try:
            if self.fleet.forget(robot):
                rospy.loginfo("%s: fleet robot %s withdrew its footprint (sourceId %s)", self.config.robot_name,
                              robot, topic.source_id)
                self.fleet_robots.publish(fleet_robots_message(self.fleet.robots(), rospy.get_time(),
                                                                self.footprint_config.robot_timeout))
        except rospy.ROSException:
            # While the launch shuts down, peers' bridges withdraw their footprints as rospy closes our topics
            # (/rosout and fleet_robots, before is_shutdown() turns true): nobody is left to tell, so that is no
            # error. Any other time it is one.
            if not node_shutting_down():
                raise

    def _footprint_tick(self, _event=None):
        """At footprint_rate: advertise this robot's footprint while it is fresh, forget silent fleet
        robots, publish the fleet robots for the layer."""
        now = rospy.get_time()
        own = self._own_footprint
        if self.footprint_config.advertise and own is not None:
            age = now - own[1]
            if 0.0 <= age <= self.footprint_config.robot_timeout:
                # The heartbeat: at the rate while moving, rarely while parked (AdvertSchedule).
                near = self._near(own[0].points)
                with self._lock:
                    valid_for = self._adverts.on_tick(own[0].points, now, near, at=own[0].stamp)
                    decision = self._adverts.decision
                if valid_for is not None:
                    self._advertise(own[0], own[0].stamp, valid_for, decision)
                self._stale_logged = False
            elif not self._stale_logged:
                self._stale_logged = True
                self._count("footprint_stale")
                # peers keep a parked robot for its advert's validFor: tell them it is gone now
                with self._lock:
                    parked = self._adverts.last_valid_for > 0
                if parked:
                    self.client.withdraw_footprint()
                rospy.logwarn("%s: no footprint on %s for %.1f s; not advertising an old pose",
                              self.config.robot_name, self.footprint_config.topic, age)
        for name in self.fleet.expire():
            self._count("fleet_robots_forgotten")
            rospy.loginfo("%s: fleet robot %s forgotten: not heard for robot_timeout %.1f s",
                          self.config.robot_name, name, self.footprint_config.robot_timeout)
        self.fleet_robots.publish(fleet_robots_message(self.fleet.robots(), now, self.footprint_config.robot_timeout))

    def _moving_peers_tick(self, _event=None):
        """At MOVING_PEERS_RATE while a known robot drives on a dead-reckoned advert: its footprint where it is now,
        so that the layer's view of it lags by footprint_min_move plus a tenth of a second of driving, not by the
        footprint_rate tick (0.5 s: 0.33 m at 0.65 m/s)."""
        robots = self.fleet.robots()
        if any(r.footprint.moving for r in robots):
            self.fleet_robots.publish(fleet_robots_message(robots, rospy.get_time(), self.footprint_config.robot_timeout))

    def _on_to_fleet(self, msg):
        try:
            update = msg_to_update(msg)
        except ValueError as err:
            reason = err.reason if isinstance(err, CoatyError) else "invalid"
            self._count("dropped_to_fleet." + reason)
            rospy.logwarn("%s: to_fleet obstacle %r v%s not published: %s", self.config.robot_name,
                          msg.uuid[:40], msg.version, err)
            return
        if update.source != self.config.robot_name:
            # Only this robot's own updates go out: re-publishing an external one echoes n(n-1) times.
            self._count("dropped_to_fleet.foreign_source")
            rospy.logwarn("%s: to_fleet obstacle %s v%d has source %r, not this robot; not re-published",
                          self.config.robot_name, update.uuid, update.version, update.source)
            return
        self.client.publish_obstacle(update)

    def _on_obstacle_list(self, msg):
        updates = []
        for item in msg.obstacles:
            if item.source == MASTER_CONTROL:
                # master control tells every robot its areas itself; answered by a robot they would go out under
                # that robot's name (issue 43, item 2)
                continue
            if not item.marked_indexes:
                # An obstacle emptied by raytracing draws nothing on a late joiner; a fleet
                # message without cells is refused by every receiver anyway.
                continue
            try:
                updates.append(msg_to_update(item))
            except ValueError as err:
                self._count("dropped_list_item")
                rospy.logwarn("%s: shared_obstacle_list item %r skipped: %s", self.config.robot_name,
                              item.uuid[:40], err)
        self.client.set_current_obstacles(updates, as_of=self._list_as_of(msg.header.stamp))

    def _list_as_of(self, stamp):
        """Client-clock time at which the list's deadlines were valid. The handler ages them to
        header.stamp (ROS time); a latched list can be old when it reaches a bridge that started
        later, so its age is taken off. A zero stamp (unknown) counts as now."""
        age = 0.0
        if not stamp.is_zero():
            age = max(0.0, rospy.get_time() - stamp.to_sec())
        return self.client.clock() - age

    def _new_source_drops(self, counters):
        """'robot_9@1a2b3c4d: 3785 dropped_source_rate_limited' for the senders whose excess was dropped
        since the last report (issue 27, item 3), the three largest; "" when none."""
        per_sender = {k: n for k, n in counters.items() if k.startswith(SENDER_DROPS)}
        last = self._sender_drops_reported
        self._sender_drops_reported = per_sender
        new = sorted(((n - last.get(k, 0), k) for k, n in per_sender.items() if n > last.get(k, 0)), reverse=True)
        return ", ".join("%s: %d %s" % (k.split(".", 1)[1], n, k.split(".", 1)[0]) for n, k in new[:3])

    def _publish_diagnostics(self, _event=None):
        counters = self.client.counters()
        with self._lock:
            counters.update(self._counters)
        status = DiagnosticStatus()
        status.name = "coaty_bridge: %s" % self.config.robot_name
        status.hardware_id = self.client.identity_id
        level, problem, errors = self.from_fleet.report()
        delivery = dict(("delivery_error." + reason, n) for reason, n in errors.items())
        counters.update(delivery)
        counters.update(self.client.liveness.values())
        counters["delivered"] = self.from_fleet.delivered
        counters["publishers_repaired"] = self.from_fleet.repaired
        counters["publishers_recreated"] = self.from_fleet.recreated
        flood = self._new_source_drops(counters)
        login_level, login_problem = self.client.login_alerts.status()
        # Every current problem is reported, the worst sets the level: a login alert must not hide
        # the sender flooding right now, nor the other way round (issue 43).
        problems = []
        if level == safe_publisher.ERROR:
            problems.append((DiagnosticStatus.ERROR, problem))
        elif level == safe_publisher.WARN:
            problems.append((DiagnosticStatus.WARN, problem))
        if self.client.tls_problem and not self.client.connected:
            # an absent, unreadable or expired certificate or key (issue 43, item 9): which file, what, what to do
            problems.append((DiagnosticStatus.ERROR, "not connected to %s: %s"
                             % (self.config.broker_url, self.client.tls_problem)))
        if login_level:
            # another connection under this robot's login (issue 43, item 6): WARN once, ERROR when repeated
            problems.append((DiagnosticStatus.ERROR if login_level >= 2 else DiagnosticStatus.WARN, login_problem))
        if flood:
            # a flooding sender (issue 27, item 3) or one claiming what it could not see (issue 43): name it
            problems.append((DiagnosticStatus.WARN, "dropping a sender's excess or implausible cells: " + flood))
        if self.client.connected:
            # connected is not enough (issue 27, attack 6): do heartbeats cross the bus?
            live, reason = self.client.liveness.status()
            if live == liveness.ERROR:
                problems.append((DiagnosticStatus.ERROR, "connected to %s but %s" % (self.config.broker_url, reason)))
            elif live == liveness.WARN:
                problems.append((DiagnosticStatus.WARN, "connected to %s but %s" % (self.config.broker_url, reason)))
        elif not (self.client.tls_problem and not self.client.connected):
            problems.append((DiagnosticStatus.WARN, "not connected to %s" % self.config.broker_url))
        if problems:
            status.level = max(level_ for level_, _ in problems)
            status.message = "; ".join(message for _, message in problems)
        else:
            status.level = DiagnosticStatus.OK
            status.message = "connected to %s" % self.config.broker_url
        status.values = [KeyValue(key, str(value)) for key, value in sorted(counters.items())]
        array = DiagnosticArray()
        array.header.stamp = rospy.Time.now()
        array.status = [status]
        self.diagnostics.publish(array)


MAX_SUBSCRIBER_WAIT = 3600.0


def checked_subscriber_wait(value):
    """~subscriber_wait in s, 0..MAX_SUBSCRIBER_WAIT; a ValueError naming it otherwise."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value <= MAX_SUBSCRIBER_WAIT:
        raise ValueError("parameter subscriber_wait = %r: must be 0..%g seconds" % (value, MAX_SUBSCRIBER_WAIT))
    return float(value)


def main():
    rospy.init_node("coaty_bridge")
    handler = RosoutHandler()
    handler.setFormatter(logging.Formatter("%(message)s"))
    for name in ("coaty_bridge", "sharing_msgs"):
        package_logger = logging.getLogger(name)
        package_logger.addHandler(handler)
        package_logger.setLevel(logging.INFO)
    try:
        config, _choice = read_config()
        footprint_config = FootprintConfig.from_params()
        subscriber_wait = checked_subscriber_wait(rospy.get_param("~subscriber_wait", 10.0))
    except ValueError as err:
        rospy.logfatal("coaty_bridge: bad parameter: %s", err)
        sys.exit(2)
    node = BridgeNode(config, footprint_config)
    publisher_links.start_watch(rospy.get_name())
    rospy.on_shutdown(node.shutdown)
    node.start(subscriber_wait)
    rospy.spin()
