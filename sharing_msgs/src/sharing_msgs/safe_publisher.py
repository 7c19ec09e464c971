"""A publisher wrapper that one bad message can never break.

Why: rospy's publisher serialises into one buffer that it resets only after a successful
write. A message that fails to serialise (a stamp >= 2**32 s, a uint32 field out of range)
raises out of ``publish()`` and leaves its partial bytes in that buffer; every later message is
then sent behind that garbage, the subscriber drops the connection and nothing arrives any more,
silently. ``SafePublisher`` serialises each message into a scratch buffer first and drops it
there (one log line, one counter per reason); if ``publish()`` still fails, the publisher is
replaced by a fresh one so the next message gets through.

No rospy import here: the caller passes a factory that makes the real publisher, so this
module stays usable (and testable) without a ROS graph.
"""
import io
import logging
import threading

_log = logging.getLogger(__name__)

#: Reasons a delivery can fail (counter keys).
SERIALIZATION = "serialization"
PUBLISH_FAILED = "publish_failed"


class SafePublisher:
    """``publish(msg, what)`` returns True when the message was handed to ROS, False when it
    was dropped. ``what`` names the message in the log line (robot, obstacle, version).
    ``errors`` counts drops by reason; ``consecutive_errors`` resets on every success;
    ``recreated`` counts replaced publishers."""

    def __init__(self, factory, topic="?"):
        self._factory = factory
        self._topic = topic
        self._lock = threading.Lock()
        self._publisher = factory()
        self.errors = {}
        self.delivered = 0
        self.consecutive_errors = 0
        self.recreated = 0

    @property
    def publisher(self):
        return self._publisher

    def get_num_connections(self):
        return self._publisher.get_num_connections()

    def publish(self, msg, what=""):
        try:
            msg.serialize(io.BytesIO())
        except Exception as err:  # genpy raises SerializationError, struct.error, TypeError, ...
            self._failed(SERIALIZATION, msg, what, err)
            return False
        with self._lock:
            publisher = self._publisher
        try:
            publisher.publish(msg)
        except Exception as err:  # noqa: BLE001 - whatever broke, the next message must go out
            self._failed(PUBLISH_FAILED, msg, what, err)
            self._recreate(publisher)
            return False
        with self._lock:
            self.delivered += 1
            self.consecutive_errors = 0
        return True

    def _failed(self, reason, msg, what, err):
        with self._lock:
            self.errors[reason] = self.errors.get(reason, 0) + 1
            self.consecutive_errors += 1
        _log.error("%s: dropped %s on %s: %s: %s", reason, what or type(msg).__name__, self._topic,
                   type(err).__name__, str(err)[:200])

    def _recreate(self, broken):
        try:
            broken.unregister()
        except Exception as err:  # noqa: BLE001 - it is being replaced anyway
            _log.debug("unregistering the broken publisher of %s failed: %s", self._topic, err)
        try:
            fresh = self._factory()
        except Exception as err:  # noqa: BLE001 - keep the old one; the next publish retries
            _log.error("could not recreate the publisher of %s: %s", self._topic, err)
            return
        with self._lock:
            self._publisher = fresh
            self.recreated += 1
        _log.warning("publisher of %s recreated after a failed publish", self._topic)
