"""Catching up on entering obstacle areas, heard only by the robots that can answer (issue 46, traffic).

A robot whose 3 x 3 obstacle areas gain new ones asks for the updates made there while it was away, and each
robot replays its own (the late joiners' catch-up, per area). Asked with a Discover, every robot received every
driving robot's request, since a Coaty Discover has no filter level: about 23 kB per robot per minute at 100
robots with a quarter of them driving (bench_fleet_scale), and growing with the fleet. So the request is a Channel
event per new area, on ``coaty/3/<ns>/CHN:org.fleetsharing.CatchUp.area_<ix>_<iy>/<sourceId>``, which only the
robots holding their own updates of obstacles in that area observe::

    {"object": {"objectType": "org.fleetsharing.CatchUpRequest", "coreType": "CoatyObject",
                "objectId": <correlation id>, "name": "catch-up"}}

They answer as to a Discover: Resolves on ``coaty/3/<ns>/RSV/<sourceId>/<correlation id>``, which the requester
subscribed to before asking (discovery.py), rate-limited per requester by the same token buckets. A robot observes
an area's channel from its first own update there until a request finds none of its updates there alive.
Bridges still answer an area Discover of an older bridge.
"""
from coaty_bridge import areas, codec
from coaty_bridge.errors import WrongTypeError
from coaty_bridge.topics import Topic, subscription

CHANNEL = "org.fleetsharing.CatchUp"
OBJECT_TYPE = "org.fleetsharing.CatchUpRequest"
#: requesters whose last request is remembered (the areas of it answered)
MAX_REQUESTERS = 4096


def channel(area):
    """The Channel id of catch-up requests for obstacle ``area`` (ix, iy)."""
    return areas.area_object_type(CHANNEL, area)


def area_of_channel(channel_id):
    """(ix, iy) of a catch-up Channel id, None for any other channel."""
    return areas.parse_area(channel_id, CHANNEL)


def request_payload(correlation_id):
    """The Channel payload asking for the updates of one area, answered on ``correlation_id``."""
    return codec.dump({"object": {"objectType": OBJECT_TYPE, "coreType": "CoatyObject",
                                  "objectId": correlation_id, "name": "catch-up"}})


def decode_request(data):
    """Channel payload dict -> the correlation id to answer on; raises an InvalidPayloadError subclass."""
    obj = codec._get(data, "object")
    if not isinstance(obj, dict):
        raise WrongTypeError("catch-up request %s is not a JSON object" % codec._short(obj))
    if codec._str(obj, "objectType") != OBJECT_TYPE:
        raise WrongTypeError("catch-up objectType %r is not %r" % (codec._short(obj["objectType"]), OBJECT_TYPE))
    correlation_id = codec._str(obj, "objectId")
    if not codec._is_uuid(correlation_id):
        raise WrongTypeError("catch-up objectId %s is not a UUID" % codec._short(correlation_id))
    return correlation_id.lower()


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

    def _ask_areas(self, new_areas):
        """Asks each of ``new_areas`` for the updates made there (one Channel event each, one correlation id)."""
        correlation_id = self._expect_resolves()
        payload = request_payload(correlation_id)
        for area in new_areas:
            self._send(str(Topic(self.config.namespace, "CHN", self.identity_id, filter=channel(area))), payload,
                       queue=False)
        self._count("catchup_requests_sent", len(new_areas))

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
        correlation_id = decode_request(data)
        if not self._catchup_allowed(topic.source_id, correlation_id, area):
            self._count("dropped.discover_rate_limited")
            return
        answers = [u for u in self._replayable_own_updates() if self._obstacle_area(u) == area]
        if not answers:
            # none of our updates there is alive any more: stop observing the area's requests
            with self._lock:
                self._catchup_areas.discard(area)
                if self._connected:
                    self._mqtt.unsubscribe(self._catchup_subscription(area))
            self._count("catchup_areas_left")
            return
        self._count("catchups_answered")
        reply = str(Topic(self.config.namespace, "RSV", self.identity_id, correlation_id=correlation_id))
        self._resolve_obstacles(reply, answers)
