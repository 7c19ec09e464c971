"""Plausible evidence on the wire (issue 43; the rule is sharing_msgs.authority.evidence, its reasoning the
sharing_msgs README, "Plausible evidence"). A part of CoatyBridgeClient (client.py).

Out: this robot's footprint adverts carry its sensor ``reach``, and before each obstacle message the bridge
makes sure every peer has heard a pose of it near the message's stamp: an advert under the plain footprint
objectType (heard fleet-wide, whatever the footprint areas), at most one per EVIDENCE_INTERVAL unless the
robot moved.
In: every footprint advert a bridge accepts is a sighting of that robot; with ``require_evidence`` a peer's
obstacle message (an Advertise or a renewal, not a Resolve restoring state) keeps only the cells within the
peer's reach of a sighting covering its stamp, and one with none left is dropped. Both are counted per
sender and named in /diagnostics.
"""
import dataclasses
import logging

from coaty_bridge import footprint as footprints
from sharing_msgs.authority import Sighting

LOG = logging.getLogger("coaty_bridge.client")

#: s between two evidence adverts while the robot stands still (a moved robot sends one at once).
EVIDENCE_INTERVAL = 1.0
#: m a robot moves before its next obstacle message brings a new evidence advert.
EVIDENCE_MOVE = 0.1
#: s an own footprint is evidence for after it arrived (the footprint topic's robot_timeout).
OWN_FOOTPRINT_MAX_AGE = 3.0


class EvidenceMixin:
    """Sightings, evidence adverts and judgements of CoatyBridgeClient."""

    def note_own_footprint(self, footprint):
        """This robot's latest footprint at its pose (the node calls it for every one it gets): the evidence
        sent before its obstacle messages."""
        with self._lock:
            self._own_footprint = (dataclasses.replace(footprint, reach=self.config.sensor_reach, valid_for=0.0),
                                   self._clock())

    def _send_evidence(self):
        """Before an obstacle message: an advert of this robot's pose under the plain footprint objectType,
        which every bridge hears, unless one went out within EVIDENCE_INTERVAL from about here."""
        now = self._clock()
        with self._lock:
            own, last = self._own_footprint, self._last_evidence
        if own is None or not 0.0 <= now - own[1] <= OWN_FOOTPRINT_MAX_AGE:
            self._count("published_without_evidence")
            if self._evidence_warned is None or now - self._evidence_warned >= 30.0:
                self._evidence_warned = now
                LOG.warning("%s: obstacle published without evidence: no footprint of this robot in the last %g s "
                            "(footprint_topic); peers that require evidence refuse what it marks or clears. Check "
                            "that move_base publishes global_costmap/footprint", self.config.robot_name,
                            OWN_FOOTPRINT_MAX_AGE)
            return False
        footprint = own[0]
        if last is not None and now - last[0] < EVIDENCE_INTERVAL and \
                footprints.largest_move(last[1], footprint.points) < EVIDENCE_MOVE and last[2] == footprint.stamp:
            return True
        payload = footprints.footprint_payload(footprint, self.footprint_object_id, self.config.footprint_object_type)
        if not self._connected:
            return False
        self._send(self._footprint_topic, payload, queue=False)
        with self._lock:
            self._last_evidence = (now, footprint.points, footprint.stamp)
        self._count("evidence_adverts_sent")
        self._count("footprint_bytes_published", len(payload))
        return True

    def _note_sighting(self, footprint):
        """A peer's footprint advert, accepted: a pose it advertised, with its reach."""
        sighting = Sighting.from_footprint(footprint.points, footprint.stamp, footprint.reach, footprint.frame_id,
                                           footprint.valid_for)
        with self._lock:
            self._poses.note(footprint.robot, sighting)

    def _judge(self, update, topic):
        """``update`` with only the cells its sender could have seen (require_evidence), or None when none is
        left; the refused cells are counted and named per sender."""
        with self._lock:
            judgement = self._poses.judge(update.source, update.stamp, update.frame_id, update.marked, update.cleared,
                                          update.resolution, update.origin_x, update.origin_y, update.size_x,
                                          update.rectangle)
        if not judgement.refused:
            return update
        key = topic.source_id or ""
        what = "obstacle %s v%d from %s: %d of %d cells refused: %s" % (
            update.uuid, update.version, update.source, judgement.refused,
            len(update.marked) + len(update.cleared), judgement.why)
        self._count("implausible_cells_refused", judgement.refused)
        if not judgement.marked and not judgement.cleared:
            self._source_drop(key, "implausible_evidence", str(topic), what)
            return None
        self._source_drop(key, "implausible_cells", str(topic), what)
        return dataclasses.replace(update, marked=judgement.marked, cleared=judgement.cleared)

