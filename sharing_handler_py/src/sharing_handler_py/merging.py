"""Merging (issue 12): obstacles, and proposals, that lie within merge_distance of a held obstacle
are one obstacle. A mixin of the SharingHandler (logic.py), whose state it works on: the held
entries, the rectangle index, the aliases of absorbed uuids, the caps and the counters.

The one with the smaller uuid absorbs the other: per cell the greater stamp wins, as if every update
of both had been sent for the surviving uuid, and later messages for the absorbed uuid are applied to
the survivor. Rectangles only grow, so two obstacles once within merge_distance stay so, and every
robot ends with the same merged obstacles whatever the order the messages came in. Merges stop at the
caps (issue 27): two obstacles whose union would exceed them stay apart.

Provenance (issue 43): only obstacles first shared by the same source merge (a merged obstacle never
shows a source that did not send its cells; master control's areas never meet robots' obstacles), and
a proposal becomes an update only of an obstacle this robot first shared. Who first shared an obstacle
is known once its first share (version 1) has arrived; until then it merges with nothing, so the groups
do not depend on the order messages arrive in.
"""
import logging

from sharing_handler_py.entry import remaining_deadline
from sharing_handler_py.errors import REFUSED
from sharing_handler_py.validation import Obstacle, check_fleet_message

_log = logging.getLogger("sharing_handler_py.logic")


class MergingMixin:
    """The SharingHandler's merging: _near and _merge_proposal for proposals, _merge_around after a
    rectangle grew or an obstacle was added."""

    def _near(self, rectangle, cells):
        """The held obstacle of this robot's (smallest uuid) whose rectangle overlaps `rectangle` or lies
        within merge_distance of it and that stays within the caps with `cells` more, or None. Another
        robot's obstacle is never one: this robot's cells under its name would show a source that did not
        send them (issue 43)."""
        near = sorted(u for u in self._nearby.near(rectangle, self._merge_distance)
                      if self._first_shared_by(self._entries[u], self.robot_name)
                      and self._mergeable(self._entries[u].rectangle, rectangle))
        for uuid in near:
            entry = self._entries[uuid]
            if self._policy.fits(entry.rectangle.union(rectangle), len(entry.present) + cells, entry.geometry,
                                 entry.source):
                return entry
        return None

    @staticmethod
    def _first_shared_by(entry, source):
        """True when the first share (version 1) of the obstacle has arrived here and came from ``source``."""
        return entry.creator_known and entry.source == source

    def _mergeable(self, a, b):
        """Rectangles that overlap, touch or lie within merge_distance (>= 0) of each other: the
        gap between overlapping ones is 0."""
        return a.gap(b) <= self._merge_distance

    def _merge_proposal(self, proposal, entry):
        """A proposal near a live obstacle is an observation of it: an update (marked cells, the
        grown rectangle, a renewed lease) sent to the fleet and to our layer, which does not
        know its proposal became an update."""
        rectangle = entry.rectangle.union(proposal.rectangle)
        update = proposal.replace(uuid=entry.uuid, version=entry.max_version + 1, source=self.robot_name,
                                  deadline=self._deadline, rectangle=rectangle, cleared=(),
                                  stamp=proposal.stamp or self._clock())
        try:
            check_fleet_message(update)
        except REFUSED as err:
            self.reject(self.robot_name, entry.uuid, err)
            return None
        self._counters["merged_proposals"] += 1
        self._counters["renewals"] += 1
        _log.info("%s: proposal %s (%d cells) lies within merge_distance %g m of obstacle %s %s: "
                  "sent as update v%d of it, rectangle now %s", self.robot_name, proposal.rectangle,
                  len(proposal.marked), self._merge_distance, entry.uuid, entry.rectangle,
                  update.version, rectangle)
        entry.apply(update)
        entry.note_deadline(self._clock(), self._deadline)
        self._to_layer(update)
        self._to_fleet(update)
        self._counters["updates_out"] += 1
        self._on_change()
        self._merge_around(entry.uuid)
        return update

    def _merge_around(self, uuid):
        """Restores the invariant "no two held obstacles lie within merge_distance, unless their
        union exceeds the caps" after the rectangle of `uuid` grew or it was added: the smaller
        uuid absorbs the other, until nothing near is left (an absorbed rectangle can reach a
        third obstacle)."""
        refused = set()  # neighbours whose union with this obstacle would exceed the caps
        while True:
            entry = self._entries[uuid]
            self._nearby.put(uuid, entry.rectangle)
            near = sorted(u for u in self._nearby.near(entry.rectangle, self._merge_distance)
                          if u != uuid and u not in refused
                          and self._first_shared_by(self._entries[u], entry.source)
                          and self._first_shared_by(entry, entry.source)
                          and self._mergeable(self._entries[u].rectangle, entry.rectangle))
            if not near:
                return uuid
            # One pair at a time: absorbing is a join, so the merged obstacle is the same in any
            # order; checked pairwise, no merge makes an obstacle larger than the caps.
            survivor, absorbed = sorted((uuid, near[0]))
            if not self._merge_fits(self._entries[survivor], self._entries[absorbed]):
                refused.add(near[0])
                continue
            self._absorb(survivor, absorbed)
            uuid = survivor

    def _merge_fits(self, a, b):
        """True when the union of two held obstacles stays within the caps; else counted and logged."""
        rectangle = a.rectangle.union(b.rectangle)
        cells = len(a.present) + len(b.present)
        if cells > self._policy.cell_cap(a.geometry, a.source):
            cells = len(a.present | b.present)
        if self._policy.fits(rectangle, cells, a.geometry, a.source):
            return True
        self._counters["merges_refused"] += 1
        _log.warning("%s: obstacles %s %s and %s %s (both from %s) lie within merge_distance but are not "
                     "merged: the union %s with %d cells exceeds the extent cap %g m or max_obstacle_cells %d",
                     self.robot_name, a.uuid, a.rectangle, b.uuid, b.rectangle, a.source, rectangle, cells,
                     self._policy.extent_cap(a.source), self._policy.cell_cap(a.geometry, a.source))
        return False

    def _absorb(self, survivor_uuid, absorbed_uuid):
        survivor, absorbed = self._entries[survivor_uuid], self._entries.pop(absorbed_uuid)
        self._nearby.remove(absorbed_uuid)
        self._quotas.removed(absorbed.owner)
        survivor.absorb(absorbed)
        self._nearby.put(survivor_uuid, survivor.rectangle)
        self._aliases[absorbed_uuid] = survivor_uuid
        self._counters["merged_obstacles"] += 1
        _log.info("%s: obstacles %s %s and %s %s lie within merge_distance %g m: merged into %s, "
                  "rectangle now %s", self.robot_name, survivor_uuid, survivor.rectangle, absorbed_uuid,
                  absorbed.rectangle, self._merge_distance, survivor_uuid, survivor.rectangle)
        # The layer holds both: it drops the absorbed one and gets its cells under the survivor's
        # uuid, with their own stamps, so its cells stay the handler's.
        self._expired_out(absorbed_uuid)
        left = remaining_deadline(survivor.expires_at - self._clock())
        by_stamp = {}
        for cell, stamp in absorbed.stamps.items():
            marked, cleared = by_stamp.setdefault(stamp, ([], []))
            (marked if cell in absorbed.present else cleared).append(cell)
        for (version, source), (marked, cleared) in sorted(by_stamp.items()):
            self._to_layer(Obstacle(uuid=survivor_uuid, marked=tuple(sorted(marked)),
                                    cleared=tuple(sorted(cleared)), deadline=left,
                                    rectangle=survivor.rectangle, source=source, geometry=survivor.geometry,
                                    version=version, frame_id=survivor.frame_id))
        self._on_change()
