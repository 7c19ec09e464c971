"""Late joiners (DESIGN.md §6): the obstacle Discover this bridge sends on every connect and on entering
new obstacle areas, and its answers to its peers' Discovers (rate-limited per requester, batched in
Resolves). A part of CoatyBridgeClient (client.py)."""
import dataclasses
import logging

from coaty_bridge import codec, lifetimes
from coaty_bridge.topics import Topic, new_uuid, resolve_subscription

LOG = logging.getLogger("coaty_bridge.client")

#: Requesters whose Discover token buckets are remembered (the quietest are forgotten beyond).
_MAX_DISCOVER_REQUESTERS = 4096
#: Obstacles per Resolve answering a Discover at most, as renewals.MAX_ENTRIES, so that no single message
#: holds a receiver for long; and bytes per Resolve at most (or max_payload_bytes if lower), so that a
#: receiver with a lower max_payload_bytes than ours still takes the batches (an obstacle larger than
#: this goes alone, as every answer went before).
RESOLVE_BATCH = 64
RESOLVE_BATCH_BYTES = 16384


class DiscoveryMixin:
    """Discovers and Resolves of CoatyBridgeClient."""

    def set_current_obstacles(self, updates, as_of=None):
        """The robot's current full obstacles, used to answer obstacle Discovers; their
        deadlines were valid at clock time `as_of` (default: now) and are aged from there."""
        current = tuple(updates)
        as_of = self._clock() if as_of is None else as_of
        with self._lock:
            self._current = current
            self._current_as_of = as_of

    def restore(self):
        """The robot's handler started again (issue 43, item 8): asks the fleet for its obstacles again (the answers
        go to it as state, not renewals) and returns this robot's own updates still alive, aged to now, for the node
        to hand over at once (its peers hold those too, but this robot may have none). Nothing while offline: the
        next connect asks anyway."""
        if not self._connected:
            return []
        self._discover_obstacles()
        self._count("restores")
        LOG.info("%s: a new subscriber of the fleet's obstacles (the handler started again?): asked the fleet for its "
                 "obstacles again", self.config.robot_name)
        return self._replayable_own_updates()

    def _discover_obstacles(self, object_types=None):
        correlation_id = self._expect_resolves()
        topic = Topic(self.config.namespace, "DSC", self.identity_id, correlation_id=correlation_id)
        self._send(str(topic), codec.discover_object_types_payload(object_types or [self.config.object_type]),
                   queue=False)
        self._count("discovers_sent")

    def _expect_resolves(self):
        """A new correlation id whose Resolves this client takes for discover_window s (a Discover's, or an area
        catch-up's: catchup.py)."""
        correlation_id = new_uuid()
        now = self._clock()
        ns = self.config.namespace
        with self._lock:
            window = self.config.discover_window
            ended = [c for c, t in self._pending_discovers.items() if not now - t < window]
            self._pending_discovers = {c: t for c, t in self._pending_discovers.items() if now - t < window}
            self._pending_discovers[correlation_id] = now
            # Only the Resolves to this Discover, subscribed before it goes out (the broker takes one connection's
            # packets in order), and no longer those of Discovers whose window has ended. With every Resolve of
            # the namespace, each robot received every catch-up of every driving robot entering new areas
            # (4.3 MB per robot per minute in the fleet_scale bench, half of 100 robots driving).
            self._mqtt.subscribe(resolve_subscription(ns, correlation_id), self._qos)
            if ended:
                self._mqtt.unsubscribe([resolve_subscription(ns, c) for c in ended])
        return correlation_id

    def _resolve_obstacles(self, reply, updates):
        """Answers a Discover with these obstacles in as few Resolves (on ``reply``) as fit: up to
        RESOLVE_BATCH objects each, the first as ``object`` and the rest as ``relatedObjects``, each within
        RESOLVE_BATCH_BYTES (an obstacle alone within max_payload_bytes). One Resolve per obstacle cost a
        joining robot a message per obstacle per robot answering, and at 40 robots about half of those never
        reached it (bench_join)."""
        objects = [codec.obstacle_to_object(u, self.config.object_type, self.config.compact_indexes) for u in updates]
        for start in range(0, len(objects), RESOLVE_BATCH):
            self._send_resolve(reply, objects[start:start + RESOLVE_BATCH])

    def _send_resolve(self, reply, objects):
        payload = codec.resolve_payload(objects[0], objects[1:])
        limit = self.config.max_payload_bytes if len(objects) == 1 else \
            min(self.config.max_payload_bytes, RESOLVE_BATCH_BYTES)
        if len(payload) > limit:
            if len(objects) == 1:
                self._count("dropped_outgoing.oversized")
                return
            half = len(objects) // 2
            self._send_resolve(reply, objects[:half])
            self._send_resolve(reply, objects[half:])
            return
        self._send(reply, payload, queue=False)
        self._count("resolves_sent")
        self._count("obstacles_resolved", len(objects))

    def _left_to_creator(self, creator, requester):
        """True when another robot's obstacle is answered by its creator alone (``discover_answers``
        "creator"): the creator is a live peer and is not the one asking (a robot's Identity advert, which
        it sends before its Discover, names it). Otherwise every robot holding it answers, as when its
        creator is gone: the fleet's copies are all that is left (under authenticate_sources, each
        under its own name: see _as_answered)."""
        if self.config.discover_answers != "creator" or creator == self.config.robot_name:
            return False
        if self._robot_of.get(requester) == creator:
            return False   # the creator itself asks: it restarted, and the fleet's copies are all it has
        return self.liveness.alive(creator)

    def _as_answered(self, update):
        """The copy of an obstacle from our list that answers a Discover. Under authenticate_sources every
        receiver drops an obstacle whose source is not the robot that sent it (forged_source), so another
        robot's obstacle goes under our name, as any update of another robot's obstacle does: same uuid,
        version and cells. Without it, a robot joining after a creator left learnt none of its obstacles."""
        if not self.config.authenticate_sources or update.source == self.config.robot_name:
            return update
        self._count("resolved_under_own_name")
        return dataclasses.replace(update, source=self.config.robot_name)

    def _discover_allowed(self, requester):
        """True when a Discover from `requester` may be answered now (its own token bucket; the
        longest-quiet requesters, whose buckets are full again, are forgotten first)."""
        with self._lock:
            return self._discover_buckets.allow(requester, self._clock())

    def _answer_discover(self, topic, request):
        if not self._discover_allowed(topic.source_id):
            self._count("dropped.discover_rate_limited")
            return
        ns = self.config.namespace
        reply = str(Topic(ns, "RSV", self.identity_id, correlation_id=topic.correlation_id))
        self._count("discovers_answered")
        if request.identity:
            self._send(reply, codec.resolve_payload(self._identity), queue=False)
            self._count("resolves_sent")
        answers = []
        if request.areas and not request.obstacles and self.config.obstacle_area_size > 0:
            # a robot entering these areas: the updates it did not hear there (each robot replays its own)
            answers = [u for u in self._replayable_own_updates() if self._obstacle_area(u) in request.areas]
        if request.obstacles:
            answers = self._replayable_own_updates()
            with self._lock:
                current, as_of = self._current, self._current_as_of
            elapsed = self._clock() - as_of
            for update in current:
                if self._left_to_creator(update.source, topic.source_id):
                    self._count("resolves_left_to_creator")
                    continue
                # the list's deadlines were valid at as_of: age them to now (a copy made from
                # a Resolve must not outlive the original)
                update = lifetimes.aged(update, elapsed)
                if update is None:
                    self._count("resolve_skipped_expired")
                    continue
                answers.append(self._as_answered(update))
        if answers:
            self._resolve_obstacles(reply, answers)
