"""What the bridge publishes: this robot's obstacle updates (fleet-wide, or to the area around the
obstacle with renewals for far robots), its footprint adverts, and the queue that keeps updates while
the broker is away. A part of CoatyBridgeClient (client.py)."""
import collections
import dataclasses
import logging
import math

import paho.mqtt.client as mqtt

from coaty_bridge import areas, codec, footprint as footprints, lifetimes, renewals, replay as replays
from coaty_bridge.topics import Topic, new_uuid, parse_topic, subscription

LOG = logging.getLogger("coaty_bridge.client")

#: Own updates kept per obstacle for Discover answers (the oldest go first beyond this).
OWN_LOG_PER_OBSTACLE = 200
# obstacles whose fleet-wide expiry is kept before expired entries are swept (a flood cannot grow it for long)
_MAX_FLEET_EXPIRIES = 400000


def _renewal_margin(deadline):
    """s before the far copies of an obstacle with ``deadline`` s left expire that its renewal is due."""
    return max(2.0, 0.1 * deadline)


class OutgoingMixin:
    """Publishing of CoatyBridgeClient."""

    def publish_obstacle(self, update, waited=False):
        """Publishes one internal ObstacleUpdate to the fleet (Advertise), fleet-wide or to the area
        around the obstacle (``_area_for``). Returns False if it was dropped (too large); queues it
        while offline."""
        if not waited and self._wait_for_evidence(update):
            return True               # sent as soon as a footprint near its stamp is here (evidence.py)
        update = self._with_evidence(update)   # where this robot stood when it saw the cells (evidence.py)
        area = self._area_for(update)
        object_type = self.config.object_type if area is None else areas.area_object_type(self.config.object_type,
                                                                                            area)
        payload = self._obstacle_payload(update, object_type)
        if len(payload) > self.config.max_payload_bytes:
            self._count("dropped_outgoing.oversized")
            LOG.warning("%s: obstacle %s v%d not published: %d bytes exceed max_payload_bytes %d",
                        self.config.robot_name, update.uuid, update.version, len(payload),
                        self.config.max_payload_bytes)
            return False
        self._count("published")
        self._count("bytes_published", len(payload))
        self._log_own(update)
        self._observe_catchup_area(update)
        if area is None:
            self._count("published_fleet_wide")
            self._sent_fleet_wide(update)
            self._send(self._obstacle_topic, payload, update=update)
        else:
            self._count("published_to_area")
            self._schedule_renewal(update)
            self._send(str(Topic(self.config.namespace, "ADV", self.identity_id, object_type=object_type)),
                       payload, update=update)
        return True

    def _obstacle_area(self, update):
        """The obstacle area (at obstacle_area_size > 0) holding the centre of the update's rectangle."""
        return areas.area_of(areas.rectangle_centre(update.rectangle), self.config.obstacle_area_size)

    def _area_for(self, update):
        """The area an update goes to, or None for fleet-wide: a first share (every robot must plan around
        it), an update that marks nothing (it may end the obstacle: far robots must stop avoiding it), and
        any update while far robots hold no live copy this bridge knows of, go to every robot."""
        if self.config.obstacle_area_size <= 0 or update.version <= 1 or not update.marked:
            return None
        with self._lock:
            far = self._fleet_expiry.get(update.uuid)
        if far is None or far <= self._clock():
            return None
        return self._obstacle_area(update)

    def _schedule_renewal(self, update):
        """An area-scoped update: when the robots near the obstacle will hold it longer than the far ones,
        renew the far copies, fleet-wide, shortly before they expire (``renew_due``)."""
        now = self._clock()
        with self._lock:
            far = self._fleet_expiry.get(update.uuid, -math.inf)
            if now + update.deadline > far:
                self._renewals[update.uuid] = (max(now, far - _renewal_margin(update.deadline)), update, now)

    def _sent_fleet_wide(self, update, now=None):
        """Every robot got ``update`` (sent or heard on the fleet-wide objectType): their copies live
        until its deadline; a renewal it covers is dropped."""
        now = self._clock() if now is None else now
        expiry = now + update.deadline
        with self._lock:
            if expiry > self._fleet_expiry.get(update.uuid, -math.inf):
                self._fleet_expiry[update.uuid] = expiry
            renewal = self._renewals.get(update.uuid)
            if renewal is not None and renewal[2] + renewal[1].deadline <= expiry + 1.0:
                del self._renewals[update.uuid]
            if len(self._fleet_expiry) > _MAX_FLEET_EXPIRIES:
                for uuid in [u for u, t in self._fleet_expiry.items() if t <= now]:
                    del self._fleet_expiry[uuid]

    def renew_due(self):
        """Sends, fleet-wide, the renewals that are due (the broker watch calls it every second), and
        with them those due within their margin, in as few renewals events as their source, frame and
        grid allow (``renewals``); returns how many obstacles were renewed. A renewal is this robot's
        last area-scoped update of the obstacle, aged. Offline, they wait (and are aged when sent)."""
        now = self._clock()
        with self._lock:
            if not self._connected:
                return 0
            due = {u: r for u, r in self._renewals.items() if r[0] <= now}
            if due:
                # renewing a little early costs nothing, a second event costs its bytes again
                due.update({u: r for u, r in self._renewals.items()
                            if r[0] - _renewal_margin(r[1].deadline) <= now})
            for uuid in due:
                del self._renewals[uuid]
        fresh_updates = []
        for uuid, (_due, update, sent_at) in due.items():
            fresh = lifetimes.aged(update, now - sent_at)
            with self._lock:
                covered = self._fleet_expiry.get(uuid, -math.inf) >= sent_at + update.deadline - 1.0
            if fresh is not None and not covered:
                fresh_updates.append(fresh)
        sent = 0
        for chunk, obj in renewals.renewals_objects(fresh_updates, new_uuid):
            payload = renewals.renewals_payload(obj)
            with self._lock:
                published = self._connected and self._mqtt.publish(
                    self._renewals_topic, payload, qos=self._qos).rc == mqtt.MQTT_ERR_SUCCESS
                if not published:
                    # not lost: due again at the next watch tick, aged from now
                    for update in chunk:
                        self._renewals.setdefault(update.uuid, (now, update, now))
            if not published:
                continue
            for update in chunk:
                self._sent_fleet_wide(update, now)
            self._count("renewals_sent", len(chunk))
            self._count("renewal_events_sent")
            self._count("bytes_published", len(payload))
            sent += len(chunk)
        return sent

    def publish_footprint(self, footprint):
        """Advertises this robot's footprint (a RobotFootprint), under the objectType of the area
        it stands in. Not queued while offline: an old pose is worth nothing. Returns False when
        it was not sent."""
        footprint = dataclasses.replace(footprint, reach=self.config.sensor_reach)
        where = footprints.centroid(footprint.points)
        self.note_own_position(where)
        object_type, topic = self.config.footprint_object_type, self._footprint_topic
        if self.config.footprint_area_size > 0:
            object_type = areas.area_object_type(object_type, areas.area_of(where, self.config.footprint_area_size))
            topic = str(Topic(self.config.namespace, "ADV", self.identity_id, object_type=object_type))
        payload = footprints.footprint_payload(footprint, self.footprint_object_id, object_type)
        if len(payload) > self.config.max_payload_bytes:
            self._count("dropped_outgoing.oversized")
            return False
        if not self._connected:
            self._count("footprints_not_sent_offline")
            return False
        self._count("footprints_published")
        self._count("footprint_bytes_published", len(payload))
        self._send(topic, payload, queue=False)
        return True

    def note_own_position(self, point):
        """This robot stands at ``point`` (x, y in the map frame): hear the footprint adverts and the
        obstacle updates of the 3 x 3 areas around it (each at its own size). Called with every own
        footprint, advertised or not. Obstacle areas new to it are asked for the updates made there
        while it was away (a Discover of those areas' objectTypes; each robot replays its own)."""
        fp_size, ob_size = self.config.footprint_area_size, self.config.obstacle_area_size
        key = (areas.area_of(point, fp_size) if fp_size > 0 else None,
               areas.area_of(point, ob_size) if ob_size > 0 else None)
        if key == (None, None) or key == self._own_area:
            return
        ns = self.config.namespace
        wanted = set()
        if fp_size > 0:
            wanted |= {subscription(ns, "ADV::" + areas.area_object_type(self.config.footprint_object_type, a))
                       for a in areas.areas_around(point, fp_size)}
        obstacle_areas = areas.areas_around(point, ob_size) if ob_size > 0 else set()
        wanted |= {subscription(ns, "ADV::" + areas.area_object_type(self.config.object_type, a))
                   for a in obstacle_areas}
        with self._lock:
            first = self._own_area is None
            if key[0] != (self._own_area or (None, None))[0]:
                self._counters["footprint_area_changes"] += 1
            self._own_area = key
            old, self._area_subscriptions = self._area_subscriptions, wanted
            new_obstacle_areas = sorted(obstacle_areas - self._obstacle_areas)
            connected = self._connected
            self._note_areas_left(self._obstacle_areas - obstacle_areas, connected)
            self._obstacle_areas = obstacle_areas
            if connected:
                # new ones first: a robot on the way in is heard from the first advert the broker has for it
                added, gone = sorted(wanted - old), sorted(old - wanted)
                if added:
                    self._mqtt.subscribe([(t, self._qos) for t in added])
                if gone:
                    self._mqtt.unsubscribe(gone)
        if connected and new_obstacle_areas and not first:
            # the first position follows the connect's own Discover, which already asked for everything
            self._ask_areas(new_obstacle_areas)
            self._count("obstacle_area_catchups")

    def withdraw_footprint(self):
        """Takes this robot's footprint back (a Deadvertise of its advert series): peers forget it now,
        not when a parked advert's validFor runs out. Returns False when not connected."""
        if not self._connected:
            return False
        self._count("footprints_withdrawn_sent")
        self._send(self._dad_topic, codec.deadvertise_payload([self.footprint_object_id]), queue=False)
        return True

    def _log_own(self, update):
        with self._lock:
            entries = self._own_log.setdefault(update.uuid, [])
            entries.append((update, self._clock()))
            if len(entries) > OWN_LOG_PER_OBSTACLE:
                del entries[0]
                self._counters["own_log_truncated"] += 1

    def _replayable_own_updates(self):
        """This robot's own updates still alive, aged to now, with what newer ones decided left out (replay.py);
        expired ones are forgotten."""
        return [u for u, _t in self._replayable_own_updates_sent()]

    def _replayable_own_updates_sent(self):
        """As _replayable_own_updates, each with the clock time it was sent."""
        now = self._clock()
        replay = []
        left_out = 0
        with self._lock:
            for uuid in list(self._own_log):
                alive = [(u, t) for u, t in self._own_log[uuid] if lifetimes.aged(u, now - t) is not None]
                if alive:
                    self._own_log[uuid] = alive
                    sent_at = {}
                    for u, t in alive:
                        sent_at[u.version] = max(t, sent_at.get(u.version, t))
                    deciding = replays.deciding_updates([lifetimes.aged(u, now - t) for u, t in alive])
                    left_out += len(alive) - len(deciding)
                    replay += [(u, sent_at[u.version]) for u in deciding]
                else:
                    del self._own_log[uuid]
            if left_out:
                self._counters["replay_updates_left_out"] += left_out
        return replay

    def _obstacle_payload(self, update, object_type=None):
        return codec.advertise_payload(
            codec.obstacle_to_object(update, object_type or self.config.object_type, self.config.compact_indexes))

    def _send(self, topic, payload, queue=True, update=None, queued_at=None):
        """Publishes now, or (``queue``) keeps it while offline. An obstacle ``update`` is kept
        with the time it was queued, so its deadline is aged when it finally goes out."""
        with self._lock:
            if self._connected:
                if topic != self._echo_topic and topic != self._heartbeat_topic:
                    # before publishing: it may be back before publish() returns
                    self.liveness.own_sent(topic, payload)
                info = self._mqtt.publish(topic, payload, qos=self._qos)
                if info.rc == mqtt.MQTT_ERR_SUCCESS:
                    return
            if not queue:
                return
            if self.config.offline_queue_size == 0 or len(self._queue) >= self.config.offline_queue_size:
                self._counters["queue_drops"] += 1
                if self._queue:
                    self._queue.popleft()  # the newest update is worth more than the oldest
                else:
                    return
            self._queue.append((topic, payload, update, self._clock() if queued_at is None else queued_at))

    def _flush_queue(self):
        with self._lock:
            pending, self._queue = list(self._queue), collections.deque()
        now = self._clock()
        for topic, payload, update, queued_at in pending:
            if update is not None:
                fresh = lifetimes.aged(update, now - queued_at)
                if fresh is None:
                    # it expired on every robot while we were offline: sending it would revive it
                    self._count("queue_expired")
                    continue
                if fresh is not update:
                    # under the objectType it was queued with (an area's, or the plain one)
                    payload = self._obstacle_payload(fresh, parse_topic(topic).object_type)
                # its deadline is now valid as of now (should the send fail and re-queue it)
                self._send(topic, payload, update=fresh, queued_at=now)
            else:
                self._send(topic, payload)
