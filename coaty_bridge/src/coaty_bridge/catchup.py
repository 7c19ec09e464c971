"""Catching up on entering obstacle areas, heard only by the robots that can answer (issue 46, traffic).

A robot whose 3 x 3 obstacle areas gain new ones asks for the updates made there while it was away, and each
robot replays its own (the late joiners' catch-up, per area). Asked with a Discover, every robot received every
driving robot's request, since a Coaty Discover has no filter level: about 23 kB per robot per minute at 100
robots with a quarter of them driving (bench_fleet_scale), and growing with the fleet. So the request is a Channel
event per new area, on ``coaty/3/<ns>/CHN:org.fleetsharing.CatchUp.area_<ix>_<iy>/<sourceId>``, which only the
robots holding their own updates of obstacles in that area observe::

    {"object": {"objectType": "org.fleetsharing.CatchUpRequest", "coreType": "CoatyObject",
                "objectId": <correlation id>, "name": "catch-up", "missedFor": 37.5}}

``missedFor`` (s, optional): how long ago the robot stopped hearing that area. Until then it heard every update
made there, so the holders answer only what they sent since, with MISSED_FOR_MARGIN s to spare for the messages
under way when it left; without it (a first visit, an area left too long ago to remember, an older bridge), they
answer everything alive. A driving robot passing the same rows again and again got every update of every
obstacle there each time: at 100 robots with drivers passing 4 m from the parked robots, 64 kB of Resolves per
robot per minute (bench_fleet_scale --aisle-offset 4). Durations need no common clock.

They answer as to a Discover: Resolves on ``coaty/3/<ns>/RSV/<sourceId>/<correlation id>``, which the requester
subscribed to before asking (discovery.py), rate-limited per requester by the same token buckets. A robot observes
an area's channel from its first own update there until a request finds none of its updates there alive.
Bridges still answer an area Discover of an older bridge.
"""
from coaty_bridge import areas, codec
from coaty_bridge.errors import OutOfRangeError, WrongTypeError
from coaty_bridge.topics import Topic, subscription

CHANNEL = "org.fleetsharing.CatchUp"
OBJECT_TYPE = "org.fleetsharing.CatchUpRequest"
#: requesters whose last request is remembered (the areas of it answered)
MAX_REQUESTERS = 4096
#: s: an update sent up to this long before the requester left the area is answered too (it may have been under way)
MISSED_FOR_MARGIN = 5.0
#: s: the largest missedFor accepted (longer than any lease worth remembering; beyond it is out_of_range)
MAX_MISSED_FOR = 1.0e7
#: areas whose leaving time is remembered; beyond, the memory starts again (the next catch-ups ask for everything)
MAX_AREAS_LEFT = 4096


def channel(area):
    """The Channel id of catch-up requests for obstacle ``area`` (ix, iy)."""
    return areas.area_object_type(CHANNEL, area)


def area_of_channel(channel_id):
    """(ix, iy) of a catch-up Channel id, None for any other channel."""
    return areas.parse_area(channel_id, CHANNEL)


def request_payload(correlation_id, missed_for=None):
    """The Channel payload asking for the updates of one area, answered on ``correlation_id``; ``missed_for``: s
    since this robot stopped hearing the area (None: everything)."""
    obj = {"objectType": OBJECT_TYPE, "coreType": "CoatyObject", "objectId": correlation_id, "name": "catch-up"}
    if missed_for is not None:
        obj["missedFor"] = round(missed_for, 1)
    return codec.dump({"object": obj})


def decode_request(data):
    """Channel payload dict -> (the correlation id to answer on, missedFor s or None); raises an InvalidPayloadError
    subclass naming the bad field."""
    obj = codec._get(data, "object")
    if not isinstance(obj, dict):
        raise WrongTypeError("catch-up request %s is not a JSON object" % codec._short(obj))
    if codec._str(obj, "objectType") != OBJECT_TYPE:
        raise WrongTypeError("catch-up objectType %r is not %r" % (codec._short(obj["objectType"]), OBJECT_TYPE))
    correlation_id = codec._str(obj, "objectId")
    if not codec._is_uuid(correlation_id):
        raise WrongTypeError("catch-up objectId %s is not a UUID" % codec._short(correlation_id))
    missed_for = obj.get("missedFor")
    if missed_for is not None:
        missed_for = codec._num(obj, "missedFor")
        if not 0.0 <= missed_for <= MAX_MISSED_FOR:
            raise OutOfRangeError("catch-up missedFor %r s outside 0..%g" % (missed_for, MAX_MISSED_FOR))
    return correlation_id.lower(), missed_for


def answered_since(sent_at, now, missed_for):
    """Whether an own update sent at clock time ``sent_at`` answers a request made at ``now`` by a robot that stopped
    hearing the area ``missed_for`` s before (None: it heard nothing)."""
    return missed_for is None or sent_at >= now - missed_for - MISSED_FOR_MARGIN


class CatchUpMixin:
    """Area catch-up of CoatyBridgeClient: asking (on entering areas) and answering (for own updates)."""

    def _catchup_subscription(self, area):
        return subscription(self.config.namespace, "CHN:" + channel(area))

    def _catchup_topics(self):
        """The catch-up channels this robot observes now (subscribed again on every connect)."""
        return [self._catchup_subscription(a) for a in sorted(self._catchup_areas)]

    def _observe_catchup_area(self, update):
        """An own update was published: observe its area's catch-up channel, if not yet."""
        if self.config.obstacle_area_size <= 0:
            return
        area = self._obstacle_area(update)
        with self._lock:
            if area in self._catchup_areas:
                return
            self._catchup_areas.add(area)
            if self._connected:
                self._mqtt.subscribe(self._catchup_subscription(area), self._qos)

    def _note_areas_left(self, left, connected):
        """This robot stops hearing the obstacle areas ``left`` now. Only while connected: until then it heard them
        (a robot offline asks its reconnect's Discover for everything)."""
        if not left or not connected:
            return
        now = self._clock()
        if len(self._areas_left) + len(left) > MAX_AREAS_LEFT:
            self._areas_left.clear()
        for area in left:
            self._areas_left[area] = now

    def _ask_areas(self, new_areas):
        """Asks each of ``new_areas`` for the updates made there (one Channel event each, one correlation id): since
        this robot left it, where it remembers when."""
        correlation_id = self._expect_resolves()
        now = self._clock()
        asked_since = 0
        for area in new_areas:
            with self._lock:
                left = self._areas_left.pop(area, None)
            missed_for = None if left is None else max(0.0, now - left)
            asked_since += missed_for is not None
            self._send(str(Topic(self.config.namespace, "CHN", self.identity_id, filter=channel(area))),
                       request_payload(correlation_id, missed_for), queue=False)
        self._count("catchup_requests_sent", len(new_areas))
        if asked_since:
            self._count("catchup_requests_since_left", asked_since)

    def _catchup_allowed(self, requester, correlation_id, area):
        """One request (one correlation id) asks several areas in one event each: it takes one token of the
        requester's Discover bucket, and each of its areas is answered once."""
        with self._lock:
            last = self._catchup_last.get(requester)
            if last is not None and last[0] == correlation_id:
                if area in last[1]:
                    return False
                last[1].add(area)
                return True
        if not self._discover_allowed(requester):
            return False
        with self._lock:
            if len(self._catchup_last) >= MAX_REQUESTERS and requester not in self._catchup_last:
                self._catchup_last.clear()   # forgetting costs a token at most
            self._catchup_last[requester] = (correlation_id, {area})
        return True

    def _answer_catchup(self, topic, data):
        area = area_of_channel(topic.filter)
        correlation_id, missed_for = decode_request(data)
        if not self._catchup_allowed(topic.source_id, correlation_id, area):
            self._count("dropped.discover_rate_limited")
            return
        alive = [(u, t) for u, t in self._replayable_own_updates_sent() if self._obstacle_area(u) == area]
        now = self._clock()
        answers = [u for u, t in alive if answered_since(t, now, missed_for)]
        if not alive:
            # none of our updates there is alive any more: stop observing the area's requests
            with self._lock:
                self._catchup_areas.discard(area)
                if self._connected:
                    self._mqtt.unsubscribe(self._catchup_subscription(area))
            self._count("catchup_areas_left")
            # An own update published there since `alive` was read found the area still observed and did not
            # subscribe; it is logged before that check, so looking again now sees it and observes the area again.
            for update, _sent_at in self._replayable_own_updates_sent():
                if self._obstacle_area(update) == area:
                    self._observe_catchup_area(update)
                    break
            return
        if not answers:
            self._count("catchups_nothing_new")   # the requester heard all of it before it left
            return
        self._count("catchups_answered")
        reply = str(Topic(self.config.namespace, "RSV", self.identity_id, correlation_id=correlation_id))
        self._resolve_obstacles(reply, answers)
