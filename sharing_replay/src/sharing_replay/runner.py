"""The replay proper: one SharingCore + SharingHandler per robot of the bag, driven in bag order.

Per robot the wiring is the live one (fleet_nav's scan callback + the sharing_handler node):

- a scan is transformed to the global frame at its header stamp and given to
  ``SharingCore.process_scan``; monitoring updates go to ``SharingHandler.on_internal_update``;
- a trigger (stuck_feedback, move_base/recovery_status or --trigger-at) makes the *next* scan
  call ``signal_stuck(trigger time)`` and, when that starts a burst, ``propose`` at the robot's
  base pose; proposals go to ``on_proposal``;
- what the handler sends to the layer goes to ``apply_shared``, what it sends to the fleet is
  sized with the Coaty codec (plain and compact) and delivered to every other robot's
  ``on_external`` (a lossless, zero-latency broker);
- ``expire`` runs at expiry_rate in bag time. The handlers' clock is the bag time.

Scans wait in a per-robot queue until tf covers their stamp (or ``tf_wait`` seconds of bag
time have passed), so a transform recorded just after its scan is used, as a live tf listener
would. Nothing here prints; events go to ``on_event`` and counters to ``problems``.
"""
import collections
import logging
import random
import time
import uuid as uuidlib

import numpy as np

from sharing_layer_cpp import core
from sharing_replay.config import describe_map, map_differences, map_from_message, static_costs
from sharing_replay.errors import InputError, TransformError
from sharing_replay.other_robots import OtherRobots
from sharing_replay.sources import discover_robots, find_other_robots, find_triggers, robot_name_of, source_frame
from sharing_replay.tf_chain import TransformChain, yaw_of

LOG = logging.getLogger(__name__)

class _Robot:
    """One robot's layer core, handler and event queue."""

    def __init__(self, replay, ns, scan_topic):
        from sharing_handler_py.logic import SharingHandler
        from sharing_handler_py.validation import Geometry
        s = replay.settings
        self.replay = replay
        self.ns = ns
        self.name = robot_name_of(ns, s.single_robot_name)
        self.scan_topic = scan_topic
        self.base_frame = source_frame(ns, s.base_frame)
        m = replay.map
        self.geometry = core.GridGeometry(m.resolution, m.origin_x, m.origin_y, m.size_x, m.size_y)
        self.handler_geometry = Geometry(m.resolution, m.origin_x, m.origin_y, m.size_x, m.size_y)
        try:
            params = core.LayerParams(robot_name=self.name, **s.layer)
        except (TypeError, ValueError) as err:
            raise InputError("bad layer parameter: %s" % err) from None
        self.core = core.SharingCore(self.geometry, params)
        self.core.fleet_robots.set_params(margin=s.robot_exclusion_margin, timeout=s.robot_timeout,
                                          trail=s.robot_exclusion_trail)
        self.core.set_static_map(replay.static)
        # Unknown map cells (and cells near them) are never shared, as in the plugin.
        self.core.set_unknown_map(np.ascontiguousarray(m.occupancy == -1))
        rng = random.Random("%d/%s" % (s.seed, self.name))
        self.handler = SharingHandler(
            self.name, replay.clock, s.obstacle_duration, on_to_layer=self._to_layer,
            on_to_fleet=self._to_fleet, on_expired=self._expired, geometry=self.handler_geometry,
            max_cells_per_message=s.max_cells_per_message,
            uuid_factory=lambda: str(uuidlib.UUID(int=rng.getrandbits(128), version=4)))
        self.queue = collections.deque()
        self.placed_key = None   # the other robots' placement last given to the layer's exclusion
        self.stuck_pending = None
        self.scans = 0
        self.scans_dropped = 0
        self.path = []        # (x, y) of the sensor, every 10th scan, for the picture

    # --- handler outputs ------------------------------------------------------------------
    def _to_layer(self, obstacle):
        result = self.core.apply_shared(self.replay.to_core(obstacle, self.geometry), self.replay.now)
        if not result.ok:
            self.replay.count("layer_rejected")
            LOG.warning("%s: layer rejected obstacle %s from %s: %s", self.name, obstacle.uuid, obstacle.source,
                        result.error)
        if obstacle.source != self.name:
            self.replay.emit("received", self.name, uuid=obstacle.uuid, source=obstacle.source,
                             version=obstacle.version, marked=len(obstacle.marked), cleared=len(obstacle.cleared),
                             cells=int(self.core.shared_cells(obstacle.uuid).size), applied=bool(result.ok))

    def _to_fleet(self, obstacle):
        self.replay.fleet_out(self, obstacle)

    def _expired(self, uuid):
        cells = int(self.core.shared_cells(uuid).size)
        self.core.expire(uuid)
        self.replay.emit("expiry", self.name, uuid=uuid, cells=cells)

    # --- queue --------------------------------------------------------------------------------
    def drain(self, force):
        """Processes queued events in order while the head is ready (or all of them when forced)."""
        replay = self.replay
        while self.queue:
            kind, payload, t = self.queue[0]
            if kind == "scan" and not force:
                stamp = payload.header.stamp.to_sec()
                if not replay.chain.ready(replay.settings.global_frame, payload.header.frame_id, stamp) \
                        and replay.now <= stamp + replay.settings.tf_wait:
                    return
            self.queue.popleft()
            if kind == "scan":
                self._scan(payload)
            elif kind == "plan":
                self._plan(payload, t)
            else:
                self._trigger(payload, t)
            replay.flush_fleet()

    def _trigger(self, source, t):
        self.replay.emit("trigger", self.name, source=source, pending=self.stuck_pending is None)
        if self.stuck_pending is None:
            self.stuck_pending = t

    def _plan(self, msg, t):
        """A global plan (nav_msgs/Path) for the plan-blocked trigger; an empty one switches it off."""
        replay = self.replay
        frame = (msg.header.frame_id or replay.settings.global_frame).lstrip("/")
        if frame != replay.settings.global_frame:
            replay.count("plans_other_frame")
            replay.note("plans_other_frame", "%s: plan at %.3f in frame %s, not %s: ignored"
                        % (self.name, t, frame, replay.settings.global_frame))
            return
        xy = np.array([(p.pose.position.x, p.pose.position.y) for p in msg.poses], dtype=np.float64).reshape(-1, 2)
        self.core.set_plan(xy)
        replay.emit("plan", self.name, poses=int(self.core.plan_length), dropped=int(len(xy) - self.core.plan_length))

    def _pose(self, stamp, sensor_xy):
        """(x, y, error): the robot's base in the global frame at stamp, or the laser's position and
        why the base had none (counted by the caller only when it proposes from there)."""
        try:
            tr = self.replay.chain.lookup(self.replay.settings.global_frame, self.base_frame, stamp)
            return tr[0], tr[1], None
        except TransformError as err:
            return sensor_xy[0], sensor_xy[1], err

    def _count_sensor_pose(self, err):
        self.replay.count("proposals_at_sensor_pose")
        self.replay.note("proposals_at_sensor_pose", "%s: no pose of %s (%s); proposing around the laser instead"
                         % (self.name, self.base_frame, err))

    def _scan(self, msg):
        replay = self.replay
        s = replay.settings
        stamp = msg.header.stamp.to_sec()
        frame = msg.header.frame_id
        try:
            tr = replay.chain.lookup(s.global_frame, frame, stamp)
            sx, sy, sz, syaw = tr[0], tr[1], tr[2], yaw_of(tr)
            points = core.scan_to_points(np.asarray(msg.ranges), msg.angle_min, msg.angle_increment,
                                         msg.range_min, msg.range_max, sx, sy, syaw, sz)
        except TransformError as err:
            self.scans_dropped += 1
            replay.count("scans_" + err.reason)
            replay.count_frame(err.reason, frame)
            replay.note("scans_" + err.reason, "%s: scan at %.3f (frame %s) dropped: %s"
                        % (self.name, stamp, frame, err))
            return
        except ValueError as err:
            self.scans_dropped += 1
            replay.count("scans_bad")
            replay.note("scans_bad", "%s: scan at %.3f dropped: %s" % (self.name, stamp, err))
            return
        self.scans += 1
        replay.scans += 1
        if self.scans % 10 == 1:
            self.path.append((sx, sy))
        if replay.others is not None:
            # The other robots where they are at this scan: never shared, as the live fleet's layers
            # never share the robots their bridges hear of. Set anew only when one moved by a millimetre
            # or more (replace_all redraws every robot; parked ones need nothing).
            placed = replay.others.placed(stamp, self.name)
            key = tuple((name, tuple(np.round(polygon[:2].ravel(), 3))) for name, polygon, _ in placed)
            if key != self.placed_key:
                self.placed_key = key
                self.core.fleet_robots.replace_all(placed)
        outcome = self.core.process_scan((sx, sy, sz), points, stamp)
        if not outcome.origin_in_map:
            replay.count("scans_origin_off_map")
        for update in outcome.updates:
            self.handler.on_internal_update(replay.to_obstacle(update, self.handler_geometry, s.global_frame))
        if self.stuck_pending is None and not self.core.plan_length:
            return
        rx, ry, no_pose = self._pose(stamp, (sx, sy))   # one lookup per scan, for both triggers
        if self.stuck_pending is not None:
            trigger_time, self.stuck_pending = self.stuck_pending, None
            if self.core.signal_stuck(trigger_time):
                if no_pose is not None:
                    self._count_sensor_pose(no_pose)
                self._propose(self.core.propose(rx, ry), rx, ry)
        if self.core.plan_length:
            report = self.core.check_plan(rx, ry, stamp)
            if report.reason != "none":
                if report.log:
                    replay.emit("plan_trigger", self.name, reason=report.reason,
                                message=report.message)
                if report.proposals and no_pose is not None:
                    self._count_sensor_pose(no_pose)
                self._propose(report.proposals, rx, ry)

    def _propose(self, proposals, rx, ry):
        replay = self.replay
        from sharing_handler_py.validation import Obstacle, Rectangle
        for proposal in proposals:
            cells = proposal.cells
            before = self.handler.counters
            obstacle = Obstacle(uuid="", marked=tuple(cells.tolist()), cleared=(), deadline=0,
                                rectangle=Rectangle(*proposal.rectangle), source=self.name,
                                geometry=self.handler_geometry, version=0, frame_id=replay.settings.global_frame,
                                stamp=replay.now)
            # The authorisation's own event is held back so that the file reads proposal, then authorised.
            replay.hold_events()
            shared = self.handler.on_proposal(obstacle)
            held = replay.release_events()
            after = self.handler.counters
            outcome = ("merged" if after["merged_proposals"] > before["merged_proposals"] else
                       "authorised" if shared is not None else "dropped")
            replay.emit("proposal", self.name, uuid=shared.uuid if shared is not None else None,
                        cells=int(cells.size), rectangle=[round(v, 4) for v in proposal.rectangle],
                        robot_xy=[round(rx, 3), round(ry, 3)], outcome=outcome)
            for record in held:
                replay.write_event(record)


class Replay:
    """Replays one bag. ``run(source)`` returns nothing; read ``problems``, ``events``, ``obstacles``."""

    def __init__(self, settings, map_data=None, on_event=None, on_progress=None, progress_every=0.25):
        self.settings = settings
        self.map = map_data
        self.static = None
        self.on_event = on_event
        self.on_progress = on_progress
        self.progress_every = progress_every
        self.chain = TransformChain(settings.tf_max_gap, settings.tf_tolerance)
        self.now = 0.0
        self.start_time = 0.0
        self.end_time = 0.0
        self.robots = {}
        self.others = None           # OtherRobots: every robot of the bag, for the fleet-robot exclusion
        self.footprint_topics = {}   # recorded footprint topic -> robot name
        self.trigger_sources = {}    # robot name -> the trigger and plan topics found for it
        self.problems = collections.Counter()
        self.frames_failed = collections.defaultdict(collections.Counter)   # reason -> frame -> count
        self.notes = collections.defaultdict(list)                         # counter -> first lines
        self.missing_topics = []
        self.scans = 0
        self.messages = 0
        self.total_messages = 0
        self.event_counts = collections.Counter()
        self.bytes_plain = 0
        self.bytes_compact = 0
        self.fleet_messages = 0
        self.obstacles = {}          # uuid -> dict (robot, time, rectangle, cell_time{cell: t}, cleared set)
        self.wall_seconds = 0.0
        self._outbox = collections.deque()
        self._codec = None
        self._held = None

    # --- shared helpers -----------------------------------------------------------------------
    def clock(self):
        return self.now

    def count(self, name, n=1):
        self.problems[name] += n

    def count_frame(self, reason, frame):
        self.frames_failed[reason][frame or "(empty)"] += 1

    def note(self, counter, line):
        lines = self.notes[counter]
        if len(lines) < 5:
            lines.append(line)
            LOG.warning("%s", line)

    def emit(self, event, robot, **fields):
        self.event_counts[event] += 1
        record = {"time": round(self.now, 6), "t": round(self.now - self.start_time, 6), "robot": robot,
                  "event": event}
        record.update(fields)
        if self._held is not None:
            self._held.append(record)
        else:
            self.write_event(record)

    def write_event(self, record):
        if self.on_event is not None:
            self.on_event(record)

    def hold_events(self):
        self._held = []

    def release_events(self):
        held, self._held = self._held or [], None
        return held

    @staticmethod
    def to_core(obstacle, geometry):
        return core.ObstacleUpdate(obstacle.uuid, np.asarray(obstacle.marked, dtype=np.uint32),
                                   np.asarray(obstacle.cleared, dtype=np.uint32), obstacle.deadline,
                                   obstacle.rectangle.as_list(), obstacle.source, geometry, obstacle.version,
                                   obstacle.stamp)

    @staticmethod
    def to_obstacle(update, geometry, frame_id):
        from sharing_handler_py.validation import Obstacle, Rectangle
        return Obstacle(uuid=update.uuid, marked=tuple(update.marked.tolist()),
                        cleared=tuple(update.cleared.tolist()), deadline=update.deadline,
                        rectangle=Rectangle(*update.rectangle), source=update.source, geometry=geometry,
                        version=update.version, frame_id=frame_id, stamp=update.stamp)

    def payload_sizes(self, obstacle):
        """Bytes of the Coaty Advertise payload of one fleet message: (plain, compact)."""
        if self._codec is None:
            from coaty_bridge import codec
            self._codec = codec
        codec = self._codec
        g = obstacle.geometry
        update = codec.ObstacleUpdate(
            uuid=obstacle.uuid, source=obstacle.source, version=obstacle.version, stamp=max(0.0, obstacle.stamp),
            frame_id=obstacle.frame_id, deadline=obstacle.deadline, rectangle=tuple(obstacle.rectangle.as_list()),
            resolution=g.resolution, origin_x=g.origin_x, origin_y=g.origin_y, size_x=g.size_x, size_y=g.size_y,
            marked=obstacle.marked, cleared=obstacle.cleared)
        plain = len(codec.advertise_payload(codec.obstacle_to_object(update, compact_indexes=False)))
        compact = len(codec.advertise_payload(codec.obstacle_to_object(update, compact_indexes=True)))
        return plain, compact

    def fleet_out(self, robot, obstacle):
        plain, compact = self.payload_sizes(obstacle)
        self.bytes_plain += plain
        self.bytes_compact += compact
        self.fleet_messages += 1
        cells = int(robot.core.shared_cells(obstacle.uuid).size)
        if obstacle.version == 1 and obstacle.uuid not in self.obstacles:
            self.obstacles[obstacle.uuid] = {
                "uuid": obstacle.uuid, "robot": robot.name, "time": self.now,
                "rectangle": obstacle.rectangle.as_list(), "cell_time": {}, "cleared": set(), "updates": 0}
            self.emit("authorised", robot.name, uuid=obstacle.uuid, version=1, cells=len(obstacle.marked),
                      rectangle=[round(v, 4) for v in obstacle.rectangle.as_list()], deadline=obstacle.deadline,
                      bytes_plain=plain, bytes_compact=compact)
        else:
            self.emit("update", robot.name, uuid=obstacle.uuid, version=obstacle.version,
                      marked=len(obstacle.marked), cleared=len(obstacle.cleared), cells=cells,
                      bytes_plain=plain, bytes_compact=compact)
        record = self.obstacles.get(obstacle.uuid)
        if record is not None:
            if obstacle.version > 1:
                record["updates"] += 1
            # rectangles only grow (merging): the record shows the union, as every handler holds it
            r = record["rectangle"]
            g = obstacle.rectangle.as_list()
            record["rectangle"] = [min(r[0], g[0]), min(r[1], g[1]), max(r[2], g[2]), max(r[3], g[3])]
            for cell in obstacle.marked:
                record["cell_time"].setdefault(cell, self.now)
                record["cleared"].discard(cell)
            record["cleared"].update(c for c in obstacle.cleared if c in record["cell_time"])
        self._outbox.append((robot.name, obstacle))

    def flush_fleet(self):
        while self._outbox:
            sender, obstacle = self._outbox.popleft()
            for robot in self.robots.values():
                if robot.name != sender:
                    robot.handler.on_external(obstacle)

    # --- set-up -------------------------------------------------------------------------------
    def _prepare(self, source):
        s = self.settings
        topics = source.topics()
        found = discover_robots(topics, s)
        bag_map = self._bag_map(source, topics)
        if self.map is None:
            if bag_map is None:
                raise InputError("no map: give --map <map.yaml> or --map-image <image> --resolution <m>; the bag "
                                 "has no /map topic either" if "/map" not in topics else
                                 "no map: the bag's /map topic could not be read; give --map")
            self.map = bag_map
        elif bag_map is not None:
            self._check_map(bag_map)
        self.static = np.ascontiguousarray(static_costs(self.map, s.lethal_cost_threshold, s.track_unknown_space))
        for ns in sorted(found):
            robot = _Robot(self, ns, found[ns])
            if robot.name in {r.name for r in self.robots.values()}:
                raise InputError("two namespaces give the robot name %r" % robot.name)
            self.robots[found[ns]] = robot
        self._prepare_others(topics)
        self._prepare_triggers(source, topics)
        self.tf_topics = [t for t in ("/tf", "/tf_static") if t in topics]
        if not self.tf_topics:
            self.missing_topics.append("/tf")
            LOG.warning("missing topic /tf: no scan can be placed in %s", s.global_frame)
        replayed = (list(self.robots) + list(self.trigger_topics) + list(self.plan_topics) + self.tf_topics
                    + list(self.footprint_topics))
        self.total_messages = sum(topics[t][1] for t in replayed)
        return replayed

    def _bag_map(self, source, topics):
        """The bag's latched /map (the first one), or None when it has none. An unusable one is an error
        only when it is the map to replay on; beside a given map it is noted and not compared."""
        if "/map" not in topics:
            return None
        for _topic, msg, _t in source.messages(["/map"]):
            try:
                return map_from_message(msg, "/map")
            except InputError as err:
                if self.map is None:
                    raise
                self.note("bag_map_unusable", "the bag's /map cannot be compared with the map given: %s" % err)
                return None
        return None

    def _check_map(self, bag_map):
        """A map given on the command line must be the grid the bag was recorded on: else every cell
        index (static filter, shares, near-wall counts) means another place."""
        differences = map_differences(self.map, bag_map)
        if not differences:
            return
        line = ("the map given (%s: %s) is not the bag's /map (%s): %s"
                % (self.map.source, describe_map(self.map), describe_map(bag_map), "; ".join(differences)))
        if not self.settings.allow_map_mismatch:
            raise InputError(line + ". Give the map the bag was recorded with (or leave --map out to use the "
                             "bag's), or --allow-map-mismatch to replay on the given map anyway")
        self.count("map_mismatch")
        self.note("map_mismatch", line + " (--allow-map-mismatch: replayed on the given map)")

    def _prepare_others(self, topics):
        """Every robot of the bag (not only those replayed), placed for the others' layers."""
        if not self.settings.robot_exclusion:
            return
        frames, footprint_topics = find_other_robots(topics, self.settings)
        if len(frames) > 1:   # a robot alone has nobody to exclude (its own footprint is not shared anyway)
            s = self.settings
            self.others = OtherRobots(self.chain, s.global_frame, frames, s.footprint, s.robot_timeout)
            self.footprint_topics = footprint_topics

    def _prepare_triggers(self, source, topics):
        found = find_triggers(self.robots.values(), topics, self.settings, source.start_time)
        self.trigger_topics, self.plan_topics, self.timed_triggers, self.trigger_sources, missing = found
        self.missing_topics += missing
        for topic in missing:
            LOG.warning("missing topic %s: no trigger from it, so nothing is proposed from it "
                        "(use --trigger-at to trigger by time)", topic)

    # --- run ------------------------------------------------------------------------------------
    def run(self, source):
        wall_start = time.monotonic()
        self.start_time, self.end_time = source.start_time, source.end_time
        self.now = self.start_time
        replayed = self._prepare(source)
        expiry_period = 1.0 / self.settings.expiry_rate
        next_expiry = self.start_time + expiry_period
        timed = collections.deque(self.timed_triggers)
        robots = list(self.robots.values())
        last_progress = 0.0
        for topic, msg, t in source.messages(replayed, numpy_topics=list(self.robots)):
            self.messages += 1
            if t > self.now:
                self.now = t
            while timed and timed[0][0] <= t:
                when, robot = timed.popleft()
                robot.queue.append(("trigger", "trigger_at", when))
            while self.now >= next_expiry:
                for robot in robots:
                    robot.handler.expire()
                next_expiry += expiry_period
            robot = self.robots.get(topic)
            if robot is not None:
                robot.queue.append(("scan", msg, t))
            elif topic == "/tf" or topic == "/tf_static":
                static = topic == "/tf_static"
                for transform in msg.transforms:
                    self.chain.add(transform, static=static)
            elif topic in self.plan_topics:
                self.plan_topics[topic].queue.append(("plan", msg, t))
            elif topic in self.footprint_topics:
                problem = self.others.on_footprint(self.footprint_topics[topic], msg)
                if problem:
                    self.count("footprints_bad")
                    self.note("footprints_bad", problem)
            else:
                trigger = self.trigger_topics.get(topic)
                if trigger is not None:
                    trigger[0].queue.append(("trigger", trigger[1], t))
            for r in robots:
                if r.queue:
                    r.drain(force=False)
            if self.on_progress is not None and self.messages % 64 == 0:
                wall = time.monotonic()
                if wall - last_progress >= self.progress_every:
                    last_progress = wall
                    self.on_progress(self, wall - wall_start)
        while timed:
            when, robot = timed.popleft()
            robot.queue.append(("trigger", "trigger_at", when))
        for r in robots:
            r.drain(force=True)
        self.flush_fleet()
        for name, count in source.problems.items():
            self.problems[name] += count
        for line in source.notes:
            if len(self.notes["bag"]) < 10:
                self.notes["bag"].append(line)
        if self.chain.rejected:
            self.problems["tf_rejected"] = self.chain.rejected
        if self.others is not None:
            for name in sorted(self.others.frames):
                if name in self.others.unplaced and name not in self.others.last:
                    self.count("robots_never_placed")
                    self.note("robots_never_placed", "%s: no pose of %s in %s anywhere in the bag: the other robots' "
                              "layers could not exclude it (--base-frame?)" % (name, self.others.frames[name],
                                                                              self.settings.global_frame))
        self.wall_seconds = time.monotonic() - wall_start
        if self.on_progress is not None:
            self.on_progress(self, self.wall_seconds, final=True)
