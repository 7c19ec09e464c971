"""Leases and tombstones of the SharingHandler (logic.py): when a held obstacle ends, and what its uuid
then stops. A part of SharingHandler.

Tombstones (issue 27, issue 43): an expired uuid is remembered, so that a late or replayed message
cannot bring it back on this robot only. A tombstone never stops a robot that sees the obstacle again:
a live message stamped after the tombstone that marks cells shows it again (``revived``), and this
robot's own layer marking cells of an expired obstacle shares them as a new obstacle (``reshared``).

An obstacle whose lease runs out while this robot's layer sees it occupied is ended as the expiry tick
would end it and its cells shared again as a new obstacle, whether or not the tick came first.
"""
import heapq
import logging

from sharing_handler_py.errors import REFUSED
from sharing_handler_py.validation import check_message_values

_log = logging.getLogger("sharing_handler_py.logic")


class LeasesMixin:
    """Expiry, tombstones, revival and re-sharing of SharingHandler."""

    def is_tombstoned(self, uuid):
        return uuid in self._tombstones

    def _expire_entry(self, uuid):
        """Ends a held obstacle whose lease ran out: forgotten, tombstoned, the layer told."""
        entry = self._forget(uuid)
        self._counters["expired"] += 1
        _log.info("%s: obstacle %s expired (%.3f s after arrival at %.3f)", self.robot_name, uuid,
                  entry.expires_at - entry.arrival, entry.arrival)
        self._expired_out(uuid)

    def expire(self):
        """Removes every obstacle whose deadline has passed since its local arrival (no message
        goes to the fleet; the layer is told). Returns the expired uuids, sorted."""
        now = self._clock()
        heap, entries, due = self._deadlines, self._entries, set()
        while heap and heap[0][0] <= now:
            _t, uuid = heapq.heappop(heap)
            entry = entries.get(uuid)
            if entry is not None and now >= entry.expires_at:   # else: gone, or its expiry moved since
                due.add(uuid)
        gone = sorted(due)
        for uuid in gone:
            self._expire_entry(uuid)
        tombs = self._tomb_heap
        while tombs and tombs[0][0] <= now:
            until, uuid = heapq.heappop(tombs)
            if self._tombstones.get(uuid) == until:
                del self._tombstones[uuid]
                self._tombstoned_at.pop(uuid, None)
        if len(heap) > 4 * len(entries) + 64:
            self._compact_deadlines()
        self._quota_log.flush(now)
        if gone:
            self._on_change()
        return gone

    def _compact_deadlines(self):
        """Renewals leave items of replaced expiries in the heap: rebuilt from the entries, so it stays
        O(obstacles)."""
        self._deadlines[:] = [(e.expires_at, u) for u, e in self._entries.items()]
        heapq.heapify(self._deadlines)

    def _forget(self, uuid):
        """Drops a held obstacle and returns its entry. The uuid (and those it absorbed) is remembered
        at least obstacle_duration more, so that a late message cannot resurrect the obstacle on this
        robot only; with stamps checked, until no message for it can pass the stamp check (a replay,
        issue 27)."""
        now = self._clock()
        entry = self._entries.pop(uuid)
        self._nearby.remove(uuid)
        self._quotas.removed(entry.owner)
        until = now + max(self._policy.tombstone_time, entry.deadline)
        self._tombstones[uuid] = until
        self._tombstoned_at[uuid] = now
        heapq.heappush(self._tomb_heap, (until, uuid))
        for alias in [a for a in self._aliases if self.resolve(a) == uuid]:
            del self._aliases[alias]
            self._tombstones[alias] = until
            self._tombstoned_at[alias] = now
            heapq.heappush(self._tomb_heap, (until, alias))
        return entry

    def _revive(self, obstacle):
        """Lifts the tombstone of an obstacle seen occupied after it expired here (a live mark stamped
        later): the robot that sees it again shares it again."""
        since = self._tombstoned_at.pop(obstacle.uuid)
        del self._tombstones[obstacle.uuid]
        self._counters["revived"] += 1
        _log.info("%s: obstacle %s, expired here at %.3f, seen occupied again by %s (v%d stamped %.3f): "
                  "held again", self.robot_name, obstacle.uuid, since, obstacle.source, obstacle.version,
                  obstacle.stamp)

    def _reshare(self, update):
        """This robot's layer marked cells of an obstacle that expired here (its tombstone stops peers'
        late copies, not the robot that sees it): its marked cells become a new obstacle, shared like a
        proposal, and the layer drops the expired uuid."""
        proposal = update.replace(uuid="", version=0, cleared=(), source=self.robot_name, deadline=0)
        try:
            check_message_values(proposal)
            self._check_grid(proposal)
            self._policy.check_extent(proposal.rectangle, "rectangle", self.robot_name)
            self._check_inside(proposal, "update")
        except REFUSED as err:
            self.reject(self.robot_name, update.uuid, err)
            return None
        self._counters["reshared"] += 1
        _log.info("%s: obstacle %s expired here, but this robot sees %d of its cells occupied again: shared "
                  "again as a new obstacle", self.robot_name, update.uuid, len(update.marked))
        self._expired_out(update.uuid)
        return self.on_proposal(proposal)
