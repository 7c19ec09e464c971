"""A publisher wrapper that one bad message can never break.

Why: rospy's publisher serialises into one buffer that it resets only after a successful
write. A message that fails to serialise (a stamp >= 2**32 s, a uint32 field out of range)
raises out of ``publish()`` and leaves its partial bytes in that buffer; every later message is
then sent behind that garbage, the subscriber drops the connection and nothing arrives any more,
silently. ``SafePublisher`` serialises each message into a scratch buffer first and drops it
there (one log line, one counter per reason). If ``publish()`` still fails, the partial bytes
are discarded from rospy's buffer (its subscribers stay connected, so the very next message
arrives); where that buffer cannot be reached, the publisher is replaced by a fresh one.

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

#: Health levels of a report (the node maps them to diagnostic_msgs/DiagnosticStatus levels).
OK, WARN, ERROR = 0, 1, 2
#: This many failures in a row, none delivered in between: delivery looks broken.
ERROR_AFTER_CONSECUTIVE = 3


def _discard_partial_bytes(publisher):
    """Empties rospy's per-topic serialisation buffer (``impl.buff``, a BytesIO that a failed
    publish leaves holding a partial message). True when done."""
    buff = getattr(getattr(publisher, "impl", None), "buff", None)
    if buff is None or not hasattr(buff, "truncate"):
        return False
    lock = getattr(publisher.impl, "publock", None)  # what rospy's publish() holds
    try:
        if lock is not None:
            with lock:
                buff.seek(0)
                buff.truncate(0)
        else:
            buff.seek(0)
            buff.truncate(0)
    except (ValueError, OSError):
        return False
    _log.warning("discarded a partial message from the publisher buffer of %s",
                 getattr(publisher, "name", "?"))
    return True


def node_shutting_down():
    """``shutting_down`` for a rospy node: rospy closes its topics before is_shutdown() turns true."""
    import rospy   # here only: the rest of this module runs without ROS
    return rospy.is_shutdown() or rospy.core.is_shutdown_requested()


class SafePublisher:
    """``publish(msg, what)`` returns True when the message was handed to ROS, False when it
    was dropped. ``what`` names the message in the log line (robot, obstacle, version).
    ``errors`` counts drops by reason; ``consecutive_errors`` resets on every success;
    ``repaired`` counts buffers emptied after a failed publish, ``recreated`` replaced
    publishers. ``precheck=False`` skips the scratch serialisation (tests use it to exercise
    the repair path). ``shutting_down`` (the node passes rospy's shutdown state) tells a publish
    that fails because the node is closing its topics from a real failure: that one is logged at
    INFO, not counted, and the publisher left alone (nobody is left to deliver to)."""

    def __init__(self, factory, topic="?", precheck=True, shutting_down=lambda: False):
        self._factory = factory
        self._topic = topic
        self._lock = threading.Lock()
        self._publisher = factory()
        self.errors = {}
        self.delivered = 0
        self.consecutive_errors = 0
        self.recreated = 0
        self.repaired = 0
        self._precheck = precheck
        self._shutting_down = shutting_down
        self._reported = 0
        self.not_delivered_at_shutdown = 0

    @property
    def publisher(self):
        return self._publisher

    def get_num_connections(self):
        return self._publisher.get_num_connections()

    def publish(self, msg, what=""):
        try:
            if self._precheck:
                msg.serialize(io.BytesIO())
        except Exception as err:  # genpy raises SerializationError, struct.error, TypeError, ...
            self._failed(SERIALIZATION, msg, what, err)
            return False
        with self._lock:
            publisher = self._publisher
        try:
            publisher.publish(msg)
        except Exception as err:  # noqa: BLE001 - whatever broke, the next message must go out
            if self._shutting_down():
                with self._lock:
                    self.not_delivered_at_shutdown += 1
                _log.info("%s not delivered on %s: the node is shutting down (%s)", what or type(msg).__name__,
                          self._topic, type(err).__name__)
                return False
            self._failed(PUBLISH_FAILED, msg, what, err)
            if _discard_partial_bytes(publisher):
                with self._lock:
                    self.repaired += 1
            else:
                self._recreate(publisher)
            return False
        with self._lock:
            self.delivered += 1
            self.consecutive_errors = 0
        return True

    def drop(self, reason, what, err):
        """Counts and logs a message that failed before it could be published (e.g. in the
        conversion to a ROS message), so it shows in the same report."""
        self._failed(reason, None, what, err)

    def report(self):
        """(level, message, counts) for /diagnostics since the previous report: WARN when
        messages were dropped since then, ERROR while the last ERROR_AFTER_CONSECUTIVE or more
        deliveries all failed, OK otherwise. ``counts`` maps reason -> total drops."""
        with self._lock:
            counts = dict(self.errors)
            failed = sum(counts.values())
            new, self._reported = failed - self._reported, failed
            consecutive = self.consecutive_errors
        reasons = ", ".join("%s %d" % item for item in sorted(counts.items()))
        if consecutive >= ERROR_AFTER_CONSECUTIVE:
            return ERROR, "%s: the last %d deliveries failed (%s)" % (self._topic, consecutive, reasons), counts
        if new:
            return WARN, "%s: %d messages dropped since the last report (%s)" % (self._topic, new, reasons), counts
        return OK, "", counts

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
