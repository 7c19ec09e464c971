"""One held obstacle: its cells with their stamps, its metadata and its lease (DESIGN.md §6, §6a).

Pure Python. ``Entry`` is the mutable state the SharingHandler keeps per obstacle; ``HeldObstacle`` is
the frozen view it lists. The rules that make every robot end with the same state whatever the order
messages came in (the stamp rule per cell, the metadata of the earliest share, rectangles that only
grow, the greatest lease) live here; see the SharingHandler's docstring (logic.py) for why.
"""
import heapq
import math
from dataclasses import dataclass
from typing import Tuple

from sharing_handler_py.validation import Geometry, Obstacle, Rectangle
from sharing_msgs import obstacle_rules

@dataclass(frozen=True)
class HeldObstacle:
    """An obstacle as a handler holds it (one entry of the debug list)."""

    uuid: str
    source: str            # the robot that first shared it
    version: int           # the greatest version seen
    deadline: int          # seconds, as in the message that defines the metadata (first share)
    rectangle: Rectangle   # union of every rectangle seen for it (and for obstacles it absorbed)
    geometry: Geometry
    frame_id: str
    cells: Tuple[int, ...]  # present cells, sorted
    arrival: float         # local arrival time (clock seconds)
    remaining: float       # seconds left at the time of the listing (expiry - now)

    def to_obstacle(self):
        """Full-state message: cells marked, nothing cleared, deadline = remaining seconds
        rounded down (at least 1), so a copy made from it never outlives this one by more
        than a second."""
        return Obstacle(uuid=self.uuid, marked=self.cells, cleared=(),
                        deadline=remaining_deadline(self.remaining), rectangle=self.rectangle,
                        source=self.source, geometry=self.geometry, version=self.version,
                        frame_id=self.frame_id)


def rectangles_meet(a, b):
    """Whether two rectangles overlap or touch."""
    return a.min_x <= b.max_x and b.min_x <= a.max_x and a.min_y <= b.max_y and b.min_y <= a.max_y


def remaining_deadline(remaining):
    """Seconds left -> the deadline a message carries: whole seconds rounded down (a copy must
    not outlive the original), at least 1 (0 would be refused as expiring on arrival)."""
    if not math.isfinite(remaining):
        return 1
    return int(min(obstacle_rules.MAX_UINT32, max(1, math.floor(remaining))))


def meta_key(obstacle):
    """Orders the messages of one uuid to pick the one that defines the metadata: the smallest
    stamp (version, source), then the smallest metadata for exact stamp ties."""
    return (obstacle.version, obstacle.source, tuple(obstacle.rectangle.as_list()),
            obstacle.deadline, obstacle.frame_id)


#: The metadata key of an obstacle known only from copies restoring state: greater than any real one.
UNKNOWN_KEY = (float("inf"), "", (), 0, "")


class Entry:
    """Mutable state of one held obstacle."""

    __slots__ = ("uuid", "source", "owner", "rectangle", "deadline", "geometry", "frame_id", "arrival",
                 "_expires", "_heap", "first_key", "max_version", "stamps", "present", "sorted_cells",
                 "creator_known")

    def __init__(self, obstacle, arrival, heap=None, live=True):
        self.uuid = obstacle.uuid
        self.source = obstacle.source
        self.owner = obstacle.source   # the source whose message made it here: its quota is charged
        self.rectangle = obstacle.rectangle
        self.deadline = obstacle.deadline
        self.geometry = obstacle.geometry
        self.frame_id = obstacle.frame_id
        self.arrival = arrival
        # Local expiry, a lease. Deadlines on the wire are remaining lifetimes aged to the moment
        # of sending: a renewal carries a full obstacle_duration, anything else what is left,
        # rounded down. The greatest arrival + deadline wins (see note_deadline).
        # Every value it takes goes into the handler's deadline heap, so expiry need not look at
        # every obstacle (items of values since replaced are skipped there).
        self._heap = [] if heap is None else heap
        self._expires = None
        self.expires_at = arrival + obstacle.deadline
        # (a copy restoring state says nothing of the first share: any message that does takes over)
        self.first_key = meta_key(obstacle) if live else UNKNOWN_KEY
        # Who first shared it is known once its first share (version 1) arrived as it was made (live); a copy
        # restoring state answers under the answering robot's name, so it never says who (issue 43: merges
        # follow the creator, merging.py)
        self.creator_known = live and obstacle.version == 1
        self.max_version = obstacle.version
        self.stamps = {}          # cell -> (version, source) of the update that last set it
        self.present = set()      # cells currently marked
        self.sorted_cells = ()    # cache of sorted(present); None when stale

    @property
    def expires_at(self):
        return self._expires

    @expires_at.setter
    def expires_at(self, value):
        if value != self._expires:
            self._expires = value
            heapq.heappush(self._heap, (value, self.uuid))

    def apply(self, obstacle, live=True):
        """Applies one update by the stamp rule; returns True when anything visible changed. The metadata comes only
        from live messages (a copy restoring state answers under another robot's name)."""
        stamp = obstacle.stamp_key
        stamps, present = self.stamps, self.present
        get = stamps.get
        before = len(present)
        for cell in obstacle.marked:
            old = get(cell)
            if old is None or stamp > old:
                stamps[cell] = stamp
                present.add(cell)
        changed = len(present) != before
        for cell in obstacle.cleared:
            old = get(cell)
            if old is None or stamp >= old:
                stamps[cell] = stamp
                if cell in present:
                    present.discard(cell)
                    changed = True
        if obstacle.version > self.max_version:
            self.max_version = obstacle.version
            changed = True
        changed |= self._grow(obstacle.rectangle)
        if live:
            changed |= self._take_metadata(meta_key(obstacle), obstacle.source, obstacle.deadline,
                                           obstacle.frame_id)
            if obstacle.version == 1 and self.first_key[0] == 1:
                self.creator_known = True
        if changed:
            self.sorted_cells = None
        return changed

    def absorb(self, other):
        """Joins another obstacle into this one (merging): per cell the greater (stamp, absent)
        wins, which is what applying every update of both to this uuid gives; the greatest
        version and lease, the union of the rectangles, the metadata of the earlier first share."""
        stamps, present = self.stamps, self.present
        for cell, stamp in other.stamps.items():
            old = stamps.get(cell)
            theirs = (stamp, cell not in other.present)
            if old is None or theirs > (old, cell not in present):
                stamps[cell] = stamp
                if theirs[1]:
                    present.discard(cell)
                else:
                    present.add(cell)
        self.max_version = max(self.max_version, other.max_version)
        self.expires_at = max(self.expires_at, other.expires_at)
        self.arrival = min(self.arrival, other.arrival)
        self._grow(other.rectangle)
        self._take_metadata(other.first_key, other.source, other.deadline, other.frame_id)
        self.sorted_cells = None

    def _grow(self, rectangle):
        if self.rectangle.contains(rectangle):
            return False
        self.rectangle = self.rectangle.union(rectangle)
        return True

    def _take_metadata(self, key, source, deadline, frame_id):
        # The earliest share defines the metadata, so all robots agree on it; two messages
        # with the same stamp (only a faulty peer sends them) are ordered by their metadata.
        if key[:2] <= self.first_key[:2] and key < self.first_key:
            self.first_key = key
            self.source = source
            self.deadline = deadline
            self.frame_id = frame_id
            return True
        return False

    def note_deadline(self, now, deadline):
        """An observation of this obstacle (a message marking cells) arrived at `now` saying
        `deadline` s remain (already capped by the policy): the greater lease wins."""
        self.expires_at = max(self.expires_at, now + deadline)

    def cells(self):
        if self.sorted_cells is None:
            self.sorted_cells = tuple(sorted(self.present))
        return self.sorted_cells
