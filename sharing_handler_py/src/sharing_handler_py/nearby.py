"""Which held obstacles lie near a rectangle, without looking at all of them.

Merging asks "which held obstacles lie within merge_distance of this one?" whenever an
obstacle is added or its rectangle grows. With a fleet's worth of obstacles held (1,000 for
100 robots sharing 10 each) a scan over every entry per message was most of a handler's CPU, so
rectangles are kept in square buckets of the map plane and a query only looks in the buckets
it reaches. The index answers with candidates; the caller applies its exact test.
"""
import math

#: Bucket edge in metres: a few obstacles' widths, so a query looks at a handful of buckets.
BUCKET_SIZE = 4.0

#: A rectangle spanning more buckets than this is kept aside and offered to every query, so a
#: huge (yet valid) rectangle costs one comparison per query instead of millions of buckets.
MAX_BUCKETS_PER_RECTANGLE = 1024


class RectangleIndex:
    """uuid -> rectangle, queried by nearness. Rectangles need finite coordinates."""

    def __init__(self, bucket_size=BUCKET_SIZE):
        if not (math.isfinite(bucket_size) and bucket_size > 0):
            raise ValueError("bucket_size %r must be a positive number (metres)" % (bucket_size,))
        self._size = float(bucket_size)
        self._buckets = {}    # (bx, by) -> set of uuids
        self._large = set()   # uuids of rectangles spanning too many buckets
        self._where = {}      # uuid -> (rectangle, bucket keys or None when large)

    def __len__(self):
        return len(self._where)

    def __contains__(self, uuid):
        return uuid in self._where

    def put(self, uuid, rectangle):
        """Adds `uuid` or moves it to `rectangle` (nothing to do when unchanged)."""
        old = self._where.get(uuid)
        if old is not None:
            if old[0] == rectangle:
                return
            self.remove(uuid)
        keys = self._keys(rectangle, 0.0)
        if keys is None:
            self._large.add(uuid)
        else:
            for key in keys:
                self._buckets.setdefault(key, set()).add(uuid)
        self._where[uuid] = (rectangle, keys)

    def remove(self, uuid):
        old = self._where.pop(uuid, None)
        if old is None:
            return
        keys = old[1]
        if keys is None:
            self._large.discard(uuid)
            return
        for key in keys:
            bucket = self._buckets[key]
            bucket.discard(uuid)
            if not bucket:
                del self._buckets[key]

    def near(self, rectangle, distance):
        """A set holding every uuid whose rectangle may lie within `distance` (>= 0) of
        `rectangle` along both axes (and some that do not: the caller tests exactly)."""
        found = set(self._large)
        keys = self._keys(rectangle, distance)
        if keys is None:
            found.update(self._where)
            return found
        buckets = self._buckets
        for key in keys:
            bucket = buckets.get(key)
            if bucket:
                found |= bucket
        return found

    def _keys(self, rectangle, margin):
        if not all(map(math.isfinite, (rectangle.min_x, rectangle.min_y, rectangle.max_x, rectangle.max_y))):
            return None
        size = self._size
        lo_x = math.floor((rectangle.min_x - margin) / size)
        hi_x = math.floor((rectangle.max_x + margin) / size)
        lo_y = math.floor((rectangle.min_y - margin) / size)
        hi_y = math.floor((rectangle.max_y + margin) / size)
        if (hi_x - lo_x + 1) * (hi_y - lo_y + 1) > MAX_BUCKETS_PER_RECTANGLE:
            return None
        return [(bx, by) for bx in range(lo_x, hi_x + 1) for by in range(lo_y, hi_y + 1)]
