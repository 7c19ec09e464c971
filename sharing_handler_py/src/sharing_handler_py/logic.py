"""The SharingHandler: each robot's decision point for shared obstacles (DESIGN.md §5.5-§5.11).

Pure Python: no rospy, no MQTT. The clock and the three outputs are injected, so the same
object runs in the node, in tests and in an offline bag replay.

Convergence (DESIGN.md §6): every obstacle keeps, per cell, the stamp (version, source) of the
update that last set it and whether the cell is present. An update with stamp S marks each of
its marked cells whose stamp is < S, then clears each of its cleared cells whose stamp is <= S
(so on an exact tie, absent wins). The end state of a cell is decided by the greatest stamp that
touched it, whatever the order the updates came in, and applying an update twice changes
nothing. The obstacle's metadata (rectangle, deadline, first source) comes from the message
with the smallest stamp seen for its uuid (the first share, version 1, once it has arrived),
its rectangle is the union of all rectangles seen, and its version is the greatest seen. All are
order-independent as well.

Merging (issue 12): two live obstacles whose rectangles lie within merge_distance of each other
are one obstacle. The one with the smaller uuid absorbs the other: per cell the greater stamp
wins, as if every update of both had been sent for the surviving uuid, and later messages for
the absorbed uuid are applied to the survivor. Rectangles only grow, so two obstacles once
within merge_distance stay so, and every robot ends with the same merged obstacles whatever
the order the messages came in. A proposal within merge_distance of a live obstacle of this robot's
becomes an update of it. Merges stop at the caps (issue 27): two obstacles whose union would exceed
the extent or cell caps stay apart; only there can robots that saw the obstacles in different orders
end with different groups.

Provenance (issue 43): only obstacles first shared by the same source merge, so a merged obstacle never
shows a source that did not send its cells: another robot's obstacle, or master control's area, is
never absorbed, and a proposal near another robot's obstacle is an obstacle of its own. With
``max_sensor_reach`` set, a robot's obstacle (merged or not) is at most what one robot can see across
(sharing_msgs.authority.single_robot_extent), so it cannot grow by absorbing beyond that either.

Leases (issue 12, issue 43): a live message that marks cells is an observation of the obstacle; the
robot that made it gives it a full obstacle_duration again. A held obstacle expires at the latest
arrival + deadline of any observation of it (the greatest lease wins, whatever the order). A message
that marks nothing (a clear) never changes the lease: it removes the cells it saw free and leaves the
rest as long-lived as before. Copies that restore state (``on_state``: Discover answers, a restarted
handler's own copies) are no observation: they may add an obstacle, never renew one. Which marked
cells count is the bridge's to check (plausible evidence, sharing_msgs.authority.evidence): a peer's
message reaches this handler with only the cells its sensors could have seen.

Evidence ends an obstacle (issue 26): when an update (this robot's or a peer's) leaves an
obstacle with no present cell, every cell of it was seen free, and the obstacle leaves the list,
the layer and the snapshot at once, as on expiry (no message sent). Every robot that applies the
clearing updates ends with no present cell too (the stamp rule), so it goes fleet-wide within one
delivery. The entry itself (its stamps) stays until its lease ends, so that the outcome does not
depend on the order: a later mark (a newer stamp: the block is back) shows it again everywhere,
and an older one stays cleared. The lease (obstacle_duration after the last observation) only
bounds what nobody checks.

Tombstones (issue 27, issue 43): leases.py.

Bounded authority (issue 27, sharing_msgs.authority): no peer can make an obstacle larger, longer-lived
or newer than this handler's own caps. A deadline is cut to obstacle_duration on arrival (so a
renewal reaches at most arrival + obstacle_duration), a message beyond the extent, cell or version
caps, or with a cell outside its rectangle, is dropped, and two obstacles whose union would exceed
the caps are not merged.
"""
import logging
import math
import uuid as uuidlib

from sharing_handler_py.entry import Entry, HeldObstacle, remaining_deadline  # noqa: F401 (re-exported)
from sharing_handler_py.errors import REFUSED, InvalidMessageError
from sharing_handler_py.leases import LeasesMixin
from sharing_handler_py.manual import ManualMixin
from sharing_handler_py.merging import MergingMixin
from sharing_handler_py.nearby import RectangleIndex
from sharing_handler_py.validation import Geometry, check_fleet_message, check_message_values, check_uuid, \
    check_indexes
from sharing_msgs import obstacle_rules
from sharing_msgs.authority import MASTER_CONTROL, DropReport, PeerPolicy, SourceQuotas, check_cells_inside

_log = logging.getLogger(__name__)

#: Why a message can be dropped; each has a counter "dropped_<reason>".
DROP_REASONS = (
    "malformed",            # structurally wrong (rectangle length, bad uuid text, empty source, ...)
    "empty_uuid",           # an update or fleet message without uuid
    "bad_version",          # a fleet message with version 0 (a proposal has no business there)
    "zero_deadline",        # a fleet message that would expire on arrival
    "non_finite_rectangle",
    "bad_geometry",         # resolution <= 0, NaN origin, zero size, ...
    "geometry_mismatch",    # a valid grid, but not ours
    "no_geometry",          # no grid known yet and the waiting queue is full
    "too_many_cells",       # more than max_cells_per_message indexes
    "index_out_of_range",
    "own_source",           # a fleet message claiming to come from this robot
    "expired",              # a message for an obstacle that expired here (tombstone)
    "unknown_uuid",         # an internal update for an obstacle the handler does not hold
    "empty_proposal",       # a proposal without marked cells
    "bad_stamp",            # a header stamp outside the ROS time range (or not finite)
    "rectangle_outside_grid",  # a rectangle reaching beyond the grid it names
    "empty_update",         # a fleet message without any marked or cleared cell
    # issue 27, bounded authority (sharing_msgs.authority.policy)
    "oversized_rectangle",  # a rectangle (own updates: the grown union) beyond max_obstacle_extent
    "too_many_obstacle_cells",  # a message with more cells than one obstacle may hold
    "implausible_version",  # more than max_version_step beyond the highest version seen
    "stale_stamp",          # stamped longer ago than obstacle_duration + max_clock_skew
    "future_stamp",         # stamped more than max_clock_skew ahead of our clock
    # issue 43: a message's cells lie inside its rectangle (sharing_msgs.authority.check_cells_inside)
    "cells_outside_rectangle",    # a cell whose centre lies outside the message's rectangle
    "more_cells_than_rectangle",  # more cells than the rectangle holds
    # issue 27, per-source quotas (sharing_msgs.authority.quotas): counted per source too, logged once per 10 s
    "source_quota",         # a new obstacle from a source already holding max_obstacles_per_source here
    "source_rate",          # beyond the source's token bucket (source_update_rate, source_update_burst)
    "source_queue_full",    # the node's queue for that source was full (issue 43: fair delivery, node.py)
)

#: Counters besides the drops.
EVENT_COUNTERS = ("proposals", "authorised", "manual", "updates_in", "updates_out",
                  "restamped", "expired", "deferred", "merged_proposals", "merged_obstacles", "renewals",
                  "cleared_by_evidence",  # deleted at once: an update left no present cell (issue 26)
                  "capped_deadlines",  # a peer's deadline cut to obstacle_duration
                  "merges_refused",    # two obstacles left apart: their union exceeds the caps
                  "state_copies",      # copies restoring state (on_state): applied, never a renewal
                  "revived",           # a tombstoned obstacle observed again after its tombstone
                  "reshared",          # this robot's layer marked cells of an expired obstacle: a new share
                  "clears_kept_lease",  # a message marking nothing left the lease as it was (issue 43)
                  "master_control_updates_not_shared")  # the layer's view of master control's area stays here

def _noop(*_args):
    pass


class SharingHandler(LeasesMixin, MergingMixin, ManualMixin):
    """Decides which proposals become fleet obstacles, which updates go out, what expires.

    Not thread-safe: call it from one thread (the node holds a lock around every call).

    Args:
        robot_name: this robot; the source of what it authorises.
        clock: callable returning the current time in seconds.
        obstacle_duration: seconds an authorised obstacle lives (its deadline), rounded up.
        on_to_layer(Obstacle): authorised proposals and applied external messages.
        on_to_fleet(Obstacle): authorised obstacles and internal updates.
        on_expired(str): uuid of an obstacle that expired here.
        geometry: this robot's grid, or None until known (see set_geometry).
        on_change(): called after the held list changed (add, cells, version, expiry).
        max_cells_per_message: a message with more indexes is dropped.
        uuid_factory: callable returning a new uuid string (default: lower-case uuid4).
        max_deferred: fleet messages kept while no grid is known.
        max_obstacle_extent: metres; a manual add with a larger rectangle is refused.
        merge_distance: metres; obstacles (and proposals) whose rectangles lie this close are
            one obstacle (issue 12, merging). A robot needs at least twice its inscribed radius
            to pass between two obstacles, so a smaller gap is no passage anyway.
        max_obstacle_extent, max_obstacle_cells, max_version_step, max_clock_skew, max_sensor_reach: the
            caps of every message and merge (sharing_msgs.authority.PeerPolicy); max_clock_skew None =
            stamps are not compared with the clock; max_sensor_reach 0 = robots' obstacles are bounded
            by max_obstacle_extent alone.
    """

    def __init__(self, robot_name, clock, obstacle_duration, on_to_layer, on_to_fleet, on_expired,
                 geometry=None, on_change=None, max_cells_per_message=100000, uuid_factory=None,
                 max_deferred=10000, max_obstacle_extent=10.0, merge_distance=0.5,
                 max_obstacle_cells=0, max_version_step=1000000, max_clock_skew=None,
                 max_obstacles_per_source=1000, source_update_rate=100.0, source_update_burst=2000,
                 max_sensor_reach=0.0):
        if not robot_name or not isinstance(robot_name, str):
            raise ValueError("robot_name %r must be a non-empty string" % (robot_name,))
        if not (isinstance(obstacle_duration, (int, float)) and math.isfinite(obstacle_duration)
                and obstacle_duration > 0):
            raise ValueError("obstacle_duration %r must be a positive number" % (obstacle_duration,))
        if geometry is not None and not isinstance(geometry, Geometry):
            raise ValueError("geometry %r is not a Geometry" % (geometry,))
        if isinstance(merge_distance, bool) or not isinstance(merge_distance, (int, float)) \
                or not math.isfinite(merge_distance) or merge_distance < 0:
            raise ValueError("merge_distance %r must be a number >= 0 (metres)" % (merge_distance,))
        self.robot_name = robot_name
        self._clock = clock
        self._deadline = int(math.ceil(obstacle_duration))
        self._to_layer = on_to_layer
        self._to_fleet = on_to_fleet
        self._expired_out = on_expired
        self._on_change = on_change or _noop
        self._geometry = geometry
        self._max_cells = max_cells_per_message
        self._new_uuid = uuid_factory or (lambda: str(uuidlib.uuid4()))
        self._max_deferred = max_deferred
        self._max_extent = max_obstacle_extent
        self._merge_distance = float(merge_distance)
        self._policy = PeerPolicy(max_extent=max_obstacle_extent, max_lifetime=self._deadline,
                                  max_obstacle_cells=max_obstacle_cells, max_version_step=max_version_step,
                                  max_clock_skew=max_clock_skew, max_sensor_reach=max_sensor_reach)
        self._entries = {}      # uuid -> _Entry
        self._nearby = RectangleIndex()  # uuid -> rectangle of every entry, for merging
        self._aliases = {}      # uuid of an absorbed obstacle -> uuid that absorbed it
        self._tombstones = {}   # uuid -> time until which messages for it are dropped
        self._tombstoned_at = {}  # uuid -> clock time it was tombstoned (a live mark stamped later revives it)
        self._deadlines = []    # heap of (expires_at, uuid), one item per value an entry's expiry took
        self._tomb_heap = []    # heap of (until, uuid) of the tombstones
        self._deferred = []     # fleet messages waiting for a grid
        # per-source quotas (issue 27): the robot itself is exempt (its own layer is no flood, and
        # peers give its obstacles back after a restart)
        self._quotas = SourceQuotas(max_obstacles_per_source, source_update_rate, source_update_burst,
                                    exempt=(robot_name,))
        self._quota_log = DropReport(robot_name, log=_log)
        self._counters = dict.fromkeys(EVENT_COUNTERS + tuple("dropped_" + r for r in DROP_REASONS), 0)

    # ----------------------------------------------------------------- queries

    @property
    def geometry(self):
        return self._geometry

    @property
    def counters(self):
        """A copy of all counters (events and dropped_<reason>)."""
        return dict(self._counters)

    def __len__(self):
        return len(self._entries)

    def __contains__(self, uuid):
        return uuid in self._entries

    def resolve(self, uuid):
        """The uuid of the held obstacle that absorbed `uuid` (itself when not absorbed)."""
        while uuid in self._aliases:
            uuid = self._aliases[uuid]
        return uuid

    def obstacles(self):
        """The held obstacles with a present cell, sorted by uuid (one whose every cell was seen free is
        gone from the fleet's view, though its stamps are kept until its lease ends)."""
        now = self._clock()
        return [self._held(self._entries[u], now) for u in sorted(self._entries) if self._entries[u].present]

    def get(self, uuid):
        """The held obstacle `uuid` (also one whose every cell was seen free, with no cell), or None."""
        entry = self._entries.get(uuid)
        return None if entry is None else self._held(entry, self._clock())

    def source_counters(self):
        """Quota drops per source, {"dropped_source_quota.robot_9": n, ...}, for /diagnostics."""
        return self._quota_log.counters()

    def live_per_source(self):
        """{source: obstacles held here that it created} (what max_obstacles_per_source bounds)."""
        return dict(self._quotas.live)

    # ----------------------------------------------------------------- inputs

    def set_geometry(self, geometry):
        """Sets this robot's grid (from the map). Fleet messages that waited for it are replayed."""
        if not isinstance(geometry, Geometry):
            raise ValueError("geometry %r is not a Geometry" % (geometry,))
        if self._geometry is not None and not self._geometry.matches(geometry):
            _log.warning("%s: grid changed from %s to %s; obstacles already held keep their grid",
                         self.robot_name, self._geometry, geometry)
        self._geometry = geometry
        deferred, self._deferred = self._deferred, []
        for obstacle, live in deferred:
            self.on_external(obstacle, live)

    def on_proposal(self, obstacle):
        """A new obstacle proposed by the layer. Returns the authorised Obstacle (version 1), the
        update it became when it lies within merge_distance of a live obstacle, or None when it
        was invalid."""
        self.expire()                   # as on_external: an ended obstacle is not merged into
        self._counters["proposals"] += 1
        try:
            if obstacle.uuid:
                raise InvalidMessageError("malformed", "proposal already has uuid %r" % obstacle.uuid)
            if not obstacle.marked:
                raise InvalidMessageError("empty_proposal", "no marked cells in %s" % obstacle.rectangle)
            check_message_values(obstacle)
            if self._geometry is None:
                _log.info("%s: no map yet; taking the grid of the first proposal: %s",
                          self.robot_name, obstacle.geometry)
                self.set_geometry(obstacle.geometry)
            self._check_grid(obstacle)
            # the layer's topic is open to any ROS node: the same caps as for a peer
            self._policy.check_extent(obstacle.rectangle, "proposal rectangle", self.robot_name)
            self._policy.check_cells(len(obstacle.marked), self._geometry, "proposal", self.robot_name)
            self._check_inside(obstacle, "proposal")
        except REFUSED as err:
            self.reject(obstacle.source or self.robot_name, obstacle.uuid, err)
            return None
        near = self._near(obstacle.rectangle, len(obstacle.marked))
        if near is not None:
            return self._merge_proposal(obstacle, near)
        return self._authorise(obstacle, self._deadline)

    def on_internal_update(self, obstacle):
        """An update of a held obstacle by this robot's layer: sent to the fleet, then applied.
        Returns the Obstacle sent, or None when dropped."""
        try:
            check_uuid(obstacle.uuid)
            if obstacle.uuid in self._aliases:
                # the layer still knows an obstacle that was merged into another one
                obstacle = obstacle.replace(uuid=self.resolve(obstacle.uuid))
            if obstacle.uuid in self._tombstones:
                if obstacle.marked and self._geometry is not None:
                    return self._reshare(obstacle)
                raise InvalidMessageError("expired", "obstacle %s expired here" % obstacle.uuid)
            entry = self._entries.get(obstacle.uuid)
            if entry is None:
                raise InvalidMessageError("unknown_uuid", "internal update for %s, which this "
                                          "handler does not hold" % obstacle.uuid)
            if self._geometry is None:
                raise InvalidMessageError("no_geometry", "no grid known yet")
            if entry.source == MASTER_CONTROL:
                # master control tells every robot its areas itself; this robot's view of one would go out under
                # this robot's name (issue 43, item 2)
                self._counters["master_control_updates_not_shared"] += 1
                _log.debug("%s: layer update of master control's area %s not shared", self.robot_name, obstacle.uuid)
                return None
            check_message_values(obstacle)
            self._check_grid(obstacle)
            if entry.expires_at - self._clock() < 1.0:
                if obstacle.marked:
                    # its lease ends now, but the layer sees it occupied: it ends here as the expiry tick would
                    # end it, and what is seen goes out as a new obstacle (issue 43, item 3: the robot that sees
                    # it again shares it again, whether or not the tick came first)
                    self._expire_entry(obstacle.uuid)
                    return self._reshare(obstacle)
                # deadlines travel in whole seconds: sent now it would outlive the obstacle here
                raise InvalidMessageError("expired", "obstacle %s has less than 1 s left" % obstacle.uuid)
            if obstacle.version <= entry.max_version and entry.max_version >= obstacle_rules.MAX_VERSION:
                raise InvalidMessageError("bad_version", "obstacle %s is at the last version %d"
                                          % (obstacle.uuid, entry.max_version))
            # what goes out must pass every peer's caps; the own obstacle grows by union
            self._policy.check_extent(entry.rectangle.union(obstacle.rectangle), "grown rectangle", entry.source)
            self._policy.check_cells(len(obstacle.marked) + len(obstacle.cleared), self._geometry, "update",
                                     entry.source)
            self._check_inside(obstacle, "update")
        except REFUSED as err:
            self.reject(obstacle.source or self.robot_name, obstacle.uuid, err)
            return None
        changes = {}
        if not obstacle.stamp:
            changes["stamp"] = self._clock()
        if obstacle.version <= entry.max_version:
            changes["version"] = entry.max_version + 1
            self._counters["restamped"] += 1
            _log.debug("%s: internal update of %s has version %d <= %d seen; re-stamped %d",
                       self.robot_name, obstacle.uuid, obstacle.version, entry.max_version,
                       entry.max_version + 1)
        if obstacle.source != self.robot_name:
            _log.debug("%s: internal update of %s claims source %r; set to own name",
                       self.robot_name, obstacle.uuid, obstacle.source)
            changes["source"] = self.robot_name
        # The rectangle only grows (merging): the layer may not know the latest union yet.
        # Cells seen occupied renew the lease: the update carries a full obstacle_duration.
        # Anything else goes out with the lifetime left now, so a robot that missed the first
        # share and adds the obstacle from this update does not keep it longer than we do.
        rectangle = entry.rectangle.union(obstacle.rectangle)
        if obstacle.rectangle != rectangle:
            changes["rectangle"] = rectangle
        if obstacle.marked:
            left = self._deadline
            entry.note_deadline(self._clock(), left)
            self._counters["renewals"] += 1
        else:
            left = remaining_deadline(entry.expires_at - self._clock())
        if obstacle.deadline != left:
            changes["deadline"] = left
        if changes:
            obstacle = obstacle.replace(**changes)
        try:
            # What goes out must pass the fleet check on every receiver (the same rules).
            check_fleet_message(obstacle)
        except REFUSED as err:
            self.reject(self.robot_name, obstacle.uuid, err)
            return None
        self._to_fleet(obstacle)
        self._counters["updates_out"] += 1
        rectangle = entry.rectangle
        shown = bool(entry.present)
        if entry.apply(obstacle):
            self._on_change()
        self._note_shown(entry, shown, obstacle)
        if entry.rectangle is not rectangle:
            self._merge_around(obstacle.uuid)
        return obstacle

    def on_state(self, obstacle):
        """A copy that restores state (a Discover answer through the bridge, or what the bridge kept
        for a restarted handler): applied like a fleet message, but no observation, so it may add an
        obstacle and never renews one; it cannot lift a tombstone. Returns as on_external."""
        self._counters["state_copies"] += 1
        return self.on_external(obstacle, live=False)

    def on_external(self, obstacle, live=True):
        """A message from another robot (via the bridge): added or applied, passed to the layer,
        never sent back out. ``live``: an observation as it was made (an Advertise, a renewal); a
        state copy is not (on_state). Returns True when applied now; False when dropped or deferred
        (waiting for a grid)."""
        # an obstacle whose lease ran out is gone before anything is applied or merged, not at the next tick: a
        # peer's new share must not merge into it (its clears, stamped in its own versions, would hide the new
        # marks, on this robot only)
        self.expire()
        try:
            revive = self._check_external(obstacle, live)
            if self._geometry is None:
                if len(self._deferred) >= self._max_deferred:
                    raise InvalidMessageError("no_geometry", "no grid known yet and %d messages "
                                              "already waiting" % len(self._deferred))
                self._deferred.append((obstacle, live))
                self._counters["deferred"] += 1
                _log.debug("%s: no grid yet; message %s v%d from %s waits for the map",
                           self.robot_name, obstacle.uuid, obstacle.version, obstacle.source)
                return False
            now = self._clock()
            if not self._quotas.allow_update(obstacle.source, now):
                return self._quota_drop(obstacle, "source_rate", now)
            self._check_grid(obstacle)
            if obstacle.uuid in self._aliases:
                obstacle = obstacle.replace(uuid=self.resolve(obstacle.uuid))
            entry = self._entries.get(obstacle.uuid)
            self._check_authority(obstacle, entry)
            if entry is None and not self._quotas.allow_new(obstacle.source):
                return self._quota_drop(obstacle, "source_quota", now)
        except REFUSED as err:
            self.reject(obstacle.source, obstacle.uuid, err)
            return False
        if revive:
            self._revive(obstacle)
        if obstacle.deadline > self._policy.max_lifetime:
            self._counters["capped_deadlines"] += 1
            _log.info("%s: message %s v%d from %s says %d s left; cut to obstacle_duration %d s",
                      self.robot_name, obstacle.uuid, obstacle.version, obstacle.source,
                      obstacle.deadline, self._policy.max_lifetime)
            obstacle = obstacle.replace(deadline=self._policy.cap_deadline(obstacle.deadline))
        shown = entry is not None and bool(entry.present)
        # A copy under this robot's own name is its own update handed back by its bridge after a restart (only this
        # robot publishes under its name): it says who first shared the obstacle, as a live message does.
        metadata = live or obstacle.source == self.robot_name
        if entry is None:
            entry = Entry(obstacle, self._clock(), self._deadlines, live=metadata)
            self._entries[obstacle.uuid] = entry
            self._quotas.added(entry.owner)
            entry.apply(obstacle, metadata)
            changed = grown = True
            _log.info("%s: added obstacle %s from %s (v%d, %d cells, deadline %d s)", self.robot_name,
                      obstacle.uuid, obstacle.source, obstacle.version, len(entry.present),
                      obstacle.deadline)
        else:
            rectangle, creator_known = entry.rectangle, entry.creator_known
            changed = entry.apply(obstacle, metadata)
            # a grown rectangle can reach another obstacle; a first share that arrived late makes its
            # creator known, and only then can it merge (merging.py)
            grown = entry.rectangle is not rectangle or (not creator_known and entry.creator_known)
            if live and obstacle.marked:
                entry.note_deadline(self._clock(), obstacle.deadline)   # an observation renews
            elif not obstacle.marked:
                self._counters["clears_kept_lease"] += 1
        self._counters["updates_in"] += 1
        self._to_layer(obstacle)
        if changed:
            self._on_change()
        self._note_shown(entry, shown, obstacle)
        if grown:
            # Only an added obstacle or a grown rectangle can come within merge_distance of
            # another (rectangles never shrink), so most updates need no search at all.
            self._merge_around(obstacle.uuid)
        if len(self._deadlines) > 4 * len(self._entries) + 1024:
            self._compact_deadlines()   # renewals leave stale items; amortised O(1) per update
        return True

    def _quota_drop(self, obstacle, reason, now):
        """A message beyond its source's quota: counted (in all and per source), logged at most once
        per 10 s per source and reason, state untouched. Returns False (not applied)."""
        self._counters["dropped_" + reason] += 1
        if reason == "source_queue_full":
            hint = ("its queue in this handler holds the most messages waiting per source; obstacle %s v%d dropped. "
                    "Another source's messages do not wait behind it" % (obstacle.uuid[:40], obstacle.version))
        elif reason == "source_quota":
            hint = ("it already holds %d live obstacles here (max_obstacles_per_source %d); new obstacle %s "
                    "refused. A robot sharing that many is faulty or hostile; raise ~max_obstacles_per_source "
                    "only if the fleet needs it" % (self._quotas.live[obstacle.source], self._quotas.max_obstacles,
                                                   obstacle.uuid[:40]))
        else:
            buckets = self._quotas.buckets
            hint = ("over source_update_rate %g/s (burst %d); last: obstacle %s v%d. Check what floods from "
                    "that robot, or raise ~source_update_rate / ~source_update_burst"
                    % (buckets.rate, buckets.burst, obstacle.uuid[:40], obstacle.version))
        self._quota_log.drop(obstacle.source, reason, now, hint)
        return False

    def queue_full(self, obstacle):
        """The node dropped ``obstacle`` because its source's queue was full: counted per source and logged
        at most once per 10 s per source, like the quotas."""
        return self._quota_drop(obstacle, "source_queue_full", self._clock())

    def reject(self, source, uuid, error):
        """Drops a message: one log line naming the source robot and the reason, one counter."""
        reason = error.reason if error.reason in DROP_REASONS else "malformed"
        self._counters["dropped_" + reason] += 1
        _log.warning("%s: dropped message from %r for obstacle %r: %s", self.robot_name,
                     source, (uuid or "")[:80], error)

    # ----------------------------------------------------------------- internals

    def _note_shown(self, entry, shown, obstacle):
        """After `obstacle` was applied to `entry`, which had present cells when `shown`: an obstacle left
        without a present cell leaves the list (every cell seen free, issue 26). The layer applied the same
        update and draws none of its cells either; it keeps monitoring the rectangle, so a block that comes
        back is marked again under the same uuid, which shows it again here."""
        if shown and not entry.present:
            self._counters["cleared_by_evidence"] += 1
            _log.info("%s: obstacle %s: every cell seen free (last cleared by %s, v%d, %.1f s before its lease "
                      "ended): removed from the list", self.robot_name, entry.uuid, obstacle.source,
                      obstacle.version, entry.expires_at - self._clock())
        elif not shown and entry.present and len(entry.stamps) > len(entry.present):
            _log.info("%s: obstacle %s seen occupied again by %s (v%d): shown again", self.robot_name,
                      entry.uuid, obstacle.source, obstacle.version)

    def _authorise(self, obstacle, deadline):
        # stamp = when the share was made: the layer's detection time, or now (manual adds).
        shared = obstacle.replace(uuid=self._new_uuid(), version=1, source=self.robot_name,
                                  deadline=deadline, stamp=obstacle.stamp or self._clock())
        entry = Entry(shared, self._clock(), self._deadlines)
        self._entries[shared.uuid] = entry
        self._quotas.added(entry.owner)
        entry.apply(shared)
        self._nearby.put(shared.uuid, entry.rectangle)
        self._counters["authorised"] += 1
        _log.info("%s: authorised obstacle %s %s, %d cells, deadline %d s", self.robot_name,
                  shared.uuid, shared.rectangle, len(entry.present), deadline)
        self._to_layer(shared)
        self._to_fleet(shared)
        self._on_change()
        return shared

    def _check_external(self, obstacle, live=True):
        # The same rules the bridge applies to what arrives over MQTT (neither is looser).
        check_fleet_message(obstacle)
        if live and obstacle.source == self.robot_name and obstacle.uuid in self._entries:
            # An echo, or someone else speaking for us about an obstacle we hold. An own obstacle
            # we do not hold is accepted: after a restart, peers give our obstacles back.
            raise InvalidMessageError("own_source", "message claims to come from this robot")
        revive = False
        if obstacle.uuid in self._tombstones:
            since = self._tombstoned_at.get(obstacle.uuid)
            if not (live and obstacle.marked and since is not None and obstacle.stamp > since):
                raise InvalidMessageError("expired", "obstacle %s expired here" % obstacle.uuid)
            revive = True
        self._policy.check_stamp(obstacle.stamp, self._clock())
        return revive

    def _check_authority(self, obstacle, entry):
        """The receiver's caps (issue 27) on one message: its rectangle, its cells, its version.
        Each message is judged on its own (not on what it would grow the obstacle to), so the
        verdict does not depend on the order messages arrive in and robots stay convergent;
        merges, which could join many messages' worth, are capped apart (_merge_fits)."""
        policy = self._policy
        creator = obstacle.source if entry is None else entry.source
        policy.check_extent(obstacle.rectangle, "rectangle", creator)
        policy.check_cells(len(obstacle.marked) + len(obstacle.cleared), self._geometry, "message", creator)
        policy.check_version(obstacle.version, 0 if entry is None else entry.max_version)
        self._check_inside(obstacle, "message from %s" % obstacle.source)

    def _check_inside(self, obstacle, what):
        """Every cell of the message lies inside its rectangle, no more cells than it holds (issue 43)."""
        g = self._geometry
        check_cells_inside(obstacle.rectangle, obstacle.marked, obstacle.cleared, g.resolution, g.origin_x,
                           g.origin_y, g.size_x, "%s %s v%d" % (what, obstacle.uuid or "(new)", obstacle.version))

    def _check_grid(self, obstacle):
        if not self._geometry.matches(obstacle.geometry):
            raise InvalidMessageError("geometry_mismatch", "grid %s, ours is %s"
                                      % (obstacle.geometry, self._geometry))
        check_indexes(obstacle, self._geometry, self._max_cells)

    @staticmethod
    def _held(entry, now):
        return HeldObstacle(uuid=entry.uuid, source=entry.source, version=entry.max_version,
                            deadline=entry.deadline, rectangle=entry.rectangle,
                            geometry=entry.geometry, frame_id=entry.frame_id, cells=entry.cells(),
                            arrival=entry.arrival, remaining=entry.expires_at - now)
