"""Plausible evidence on the wire (issue 43; the rule is sharing_msgs.authority.evidence, its reasoning the
sharing_msgs README, "Plausible evidence"). A part of CoatyBridgeClient (client.py).

Out: this robot's footprint adverts carry its sensor ``reach``, and each obstacle message carries its evidence
(codec: ``"evidence": [stamp, x, y, radius, reach]``), this robot's footprint taken nearest the message's stamp
(within evidence_window): where it stood when it saw the cells. It goes wherever the message goes, to a robot
started since as well, and a renewal carries its update's. A message waits for such a footprint up to
EVIDENCE_WAIT s. (Evidence went as a footprint advert of its own before each message, to every robot: 44 of
the 170 kB each of 12 robots received per minute in the scale bench, and, as adverts go fleet-wide and updates
to their area, ~330 kB at 100 robots; inside the message it is ~50 bytes where the message goes.)
In: every footprint advert a bridge accepts, and every obstacle message's evidence, is a sighting of that
robot; with ``require_evidence`` a peer's obstacle message (an Advertise or a renewal, not a Resolve restoring
state) keeps only the cells within the peer's reach of a sighting covering its stamp, and one with none left
is dropped. Both are counted per sender and named in /diagnostics.
"""
import dataclasses
import logging
import math

from coaty_bridge import lifetimes
from sharing_msgs.authority import Sighting

LOG = logging.getLogger("coaty_bridge.client")

#: s an obstacle message waits for this robot's first footprint (a robot sharing before its navigation publishes
#: one, at start-up) before it goes out without evidence
EVIDENCE_WAIT = 5.0


class EvidenceMixin:
    """Sightings, evidence adverts and judgements of CoatyBridgeClient."""

    def note_own_footprint(self, footprint):
        """This robot's latest footprint at its pose (the node calls it for every one it gets): the evidence sent
        before its obstacle messages. Messages that waited for it go out now (or wait on, if it is too old for them)."""
        with self._lock:
            self._own_footprints.append(dataclasses.replace(footprint, reach=self.config.sensor_reach, valid_for=0.0))
            waiting, self._awaiting_evidence = self._awaiting_evidence, []
        self._publish_waited(waiting)

    def expect_footprints(self, expected=True):
        """This robot advertises its footprint (the node's advertise_footprint): an obstacle message waits for one
        near its stamp (EVIDENCE_WAIT s at most)."""
        with self._lock:
            self._expect_footprints = bool(expected)

    def _evidence_for(self, update):
        """This robot's footprint taken nearest ``update``'s stamp, when within evidence_window of it (both on this
        robot's ROS clock: in simulation that is simulated time), else None. The recent ones are kept, so an update
        that waited offline still finds the pose it was made at."""
        best = min(self._own_footprints, key=lambda f: abs(update.stamp - f.stamp), default=None)
        if best is not None and abs(update.stamp - best.stamp) <= self.config.evidence_window:
            return best
        return None

    def _wait_for_evidence(self, update):
        """True when ``update`` was kept back until a footprint near its stamp arrives (at start-up before navigation
        publishes one, or when the footprint topic lags: at most EVIDENCE_WAIT s, see release_unevidenced). Sent
        without, every peer that requires evidence would refuse it for good."""
        with self._lock:
            if self._evidence_for(update) is not None or not self._expect_footprints:
                return False
            self._awaiting_evidence.append((update, self._clock()))
        self._count("awaiting_evidence")
        LOG.info("%s: obstacle %s v%d (stamp %.3f) waits for a footprint of this robot within %g s of its stamp (at most "
                 "%g s): sent without one, peers requiring evidence would refuse it", self.config.robot_name, update.uuid,
                 update.version, update.stamp, self.config.evidence_window, EVIDENCE_WAIT)
        return True

    def release_unevidenced(self):
        """Sends (without evidence, WARN) what waited EVIDENCE_WAIT s for a footprint that did not come; the broker
        watch calls it every second."""
        now = self._clock()
        with self._lock:
            due = [(u, t) for u, t in self._awaiting_evidence if now - t >= EVIDENCE_WAIT]
            self._awaiting_evidence = [(u, t) for u, t in self._awaiting_evidence if now - t < EVIDENCE_WAIT]
        for update, since in due:
            self._publish_now(update, since)

    def _publish_waited(self, waited):
        for update, since in waited:
            with self._lock:
                ready = self._evidence_for(update) is not None
                if not ready:
                    self._awaiting_evidence.append((update, since))
            if ready:
                self._publish_now(update, since)

    def _publish_now(self, update, since):
        """Publishes an update that waited, its deadline aged by the wait (a copy must not outlive the original)."""
        fresh = lifetimes.aged(update, self._clock() - since)
        if fresh is not None:
            self.publish_obstacle(fresh, waited=True)

    def _with_evidence(self, update):
        """``update`` carrying its evidence: this robot's footprint taken nearest its stamp (within evidence_window,
        in its frame), as [stamp, centroid x, centroid y, circumradius, sensor_reach]. Without such a footprint it
        goes as it is (counted; a WARN every 30 s): peers that require evidence refuse what it marks or clears."""
        if update.evidence is not None:
            return update
        with self._lock:
            own = self._evidence_for(update)
        if own is not None and own.frame_id.lstrip("/") == update.frame_id.lstrip("/"):
            pose = Sighting.from_footprint(own.points, own.stamp, own.reach, own.frame_id)
            self._count("published_with_evidence")
            return dataclasses.replace(update, evidence=(own.stamp, pose.x, pose.y, pose.radius, own.reach))
        self._count("published_without_evidence")
        if not self._expect_footprints:
            return update            # a robot that advertises no footprint has none to send (advertise_footprint)
        now = self._clock()
        if self._evidence_warned is None or now - self._evidence_warned >= 30.0:
            self._evidence_warned = now
            LOG.warning("%s: obstacle %s v%d published without evidence: no footprint of this robot in frame %r within "
                        "%g s of its stamp %.3f (footprint_topic); peers that require evidence refuse what it marks or "
                        "clears. Check that move_base publishes global_costmap/footprint", self.config.robot_name,
                        update.uuid, update.version, update.frame_id, self.config.evidence_window, update.stamp)
        return update

    def _note_sighting(self, footprint):
        """A peer's footprint advert, accepted: a pose it advertised, with its reach. A dead-reckoned advert's
        validFor promises no pose but the one at its stamp (the robot drives on): it is a sighting without one."""
        sighting = Sighting.from_footprint(footprint.points, footprint.stamp, footprint.reach, footprint.frame_id,
                                           0.0 if footprint.moving else footprint.valid_for)
        with self._lock:
            self._poses.note(footprint.robot, sighting)

    def _note_evidence(self, update, topic):
        """The evidence an obstacle message carries, noted as a sighting of its source; False (the message dropped,
        named) when it claims a footprint larger than a max_footprint_extent square, as a footprint advert may not."""
        stamp, x, y, radius, reach = update.evidence
        largest = self.config.max_footprint_extent * math.sqrt(0.5)
        if radius > largest:
            self._source_drop(topic.source_id or "", "implausible_evidence", str(topic),
                              "obstacle %s v%d from %s: its evidence claims a footprint of radius %.2f m, beyond the "
                              "%.2f m of a max_footprint_extent %g m square" % (
                                  update.uuid, update.version, update.source, radius, largest,
                                  self.config.max_footprint_extent))
            return False
        with self._lock:
            self._poses.note(update.source, Sighting(stamp, x, y, radius, reach, update.frame_id.lstrip("/")))
        return True

    def _judge(self, update, topic):
        """``update`` with only the cells its sender could have seen (require_evidence), or None when none is
        left; the refused cells are counted and named per sender. The evidence it carries counts."""
        if update.evidence is not None and not self._note_evidence(update, topic):
            return None
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

