"""A small tf buffer for offline replay: time-stamped edges of a frame tree, looked up at a stamp.

Why not tf2's BufferCore (python3-tf2-ros)? It interpolates silently across any gap in an
edge's history, so a bag where tf stopped for ten seconds would still give every scan a
(made-up) pose. A replay has to *report* such gaps with counts, and decide per scan whether
its transform is known, not yet known (wait for more of the bag) or never going to be known.
So this module keeps, per child frame, the sorted samples of its edge and answers with
tf2's semantics plus explicit limits:

- between two samples: linear interpolation of the translation, slerp of the rotation (tf2),
  but only when the samples are at most ``max_gap`` seconds apart (else ``tf_gap``);
- outside the samples: tf2 refuses to extrapolate; we accept the nearest sample when it is at
  most ``tolerance`` seconds away (fake_localization future-dates map->odom by its
  transform_tolerance, and a scan's transform often comes a few ms after it), else
  ``tf_extrapolation`` before the edge's first sample (tf not started yet) and ``tf_gap``
  after its last one (the edge stopped: the runner only asks once ``tf_wait`` seconds of bag
  have passed without a newer sample);
- static edges (/tf_static) hold for all time;
- a frame with no path to the target frame is ``tf_unconnected``.

Frame names are compared without a leading '/', as tf2 does.
"""
import bisect
import math

from sharing_replay.errors import TransformError


def _strip(frame):
    return frame[1:] if frame.startswith("/") else frame


def _compose(a, b):
    """a * b for transforms (tx, ty, tz, qx, qy, qz, qw)."""
    ax, ay, az, aqx, aqy, aqz, aqw = a
    bx, by, bz, bqx, bqy, bqz, bqw = b
    # rotate b's translation by a's rotation: v' = v + 2 w (q x v) + 2 q x (q x v)
    cx = aqy * bz - aqz * by
    cy = aqz * bx - aqx * bz
    cz = aqx * by - aqy * bx
    dx = aqy * cz - aqz * cy
    dy = aqz * cx - aqx * cz
    dz = aqx * cy - aqy * cx
    rx = bx + 2.0 * (aqw * cx + dx)
    ry = by + 2.0 * (aqw * cy + dy)
    rz = bz + 2.0 * (aqw * cz + dz)
    qw = aqw * bqw - aqx * bqx - aqy * bqy - aqz * bqz
    qx = aqw * bqx + aqx * bqw + aqy * bqz - aqz * bqy
    qy = aqw * bqy - aqx * bqz + aqy * bqw + aqz * bqx
    qz = aqw * bqz + aqx * bqy - aqy * bqx + aqz * bqw
    return (ax + rx, ay + ry, az + rz, qx, qy, qz, qw)


def _inverse(a):
    x, y, z, qx, qy, qz, qw = a
    inv_rot = (0.0, 0.0, 0.0, -qx, -qy, -qz, qw)
    tx, ty, tz = _compose(inv_rot, (x, y, z, 0.0, 0.0, 0.0, 1.0))[:3]
    return (-tx, -ty, -tz, -qx, -qy, -qz, qw)


def _interpolate(a, b, ratio):
    tx = a[0] + (b[0] - a[0]) * ratio
    ty = a[1] + (b[1] - a[1]) * ratio
    tz = a[2] + (b[2] - a[2]) * ratio
    q0, q1 = a[3:], b[3:]
    dot = sum(u * v for u, v in zip(q0, q1))
    if dot < 0.0:
        q1, dot = tuple(-v for v in q1), -dot
    if dot > 0.9995:
        q = tuple(u + (v - u) * ratio for u, v in zip(q0, q1))
    else:
        theta = math.acos(min(1.0, dot))
        s0 = math.sin((1.0 - ratio) * theta) / math.sin(theta)
        s1 = math.sin(ratio * theta) / math.sin(theta)
        q = tuple(s0 * u + s1 * v for u, v in zip(q0, q1))
    norm = math.sqrt(sum(v * v for v in q)) or 1.0
    return (tx, ty, tz) + tuple(v / norm for v in q)


def yaw_of(transform):
    _, _, _, qx, qy, qz, qw = transform
    return math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


class _Edge:
    __slots__ = ("parent", "static", "times", "values")

    def __init__(self, parent, static):
        self.parent = parent
        self.static = static
        self.times = []
        self.values = []


class TransformChain:
    """Edges child -> parent with their samples; ``lookup(target, source, stamp)``."""

    def __init__(self, max_gap=1.0, tolerance=0.2, cache_time=60.0):
        if not (max_gap > 0 and tolerance >= 0 and cache_time > 0):
            raise ValueError("TransformChain: need max_gap > 0, tolerance >= 0, cache_time > 0; got %r, %r, %r"
                             % (max_gap, tolerance, cache_time))
        self.max_gap = float(max_gap)
        self.tolerance = float(tolerance)
        self.cache_time = float(cache_time)
        self._edges = {}
        self.reparented = 0
        self.rejected = 0

    def add(self, transform_stamped, static=False):
        """Adds one geometry_msgs/TransformStamped. Returns False (and counts) for a bad one."""
        child = _strip(transform_stamped.child_frame_id)
        parent = _strip(transform_stamped.header.frame_id)
        tr = transform_stamped.transform
        value = (tr.translation.x, tr.translation.y, tr.translation.z,
                 tr.rotation.x, tr.rotation.y, tr.rotation.z, tr.rotation.w)
        norm = math.sqrt(sum(v * v for v in value[3:]))
        if not child or not parent or child == parent or not all(math.isfinite(v) for v in value) \
                or abs(norm - 1.0) > 1e-3:
            self.rejected += 1
            return False
        value = value[:3] + tuple(v / norm for v in value[3:])
        edge = self._edges.get(child)
        if edge is None or edge.parent != parent or edge.static != static:
            if edge is not None:
                self.reparented += 1
            edge = self._edges[child] = _Edge(parent, static)
        if static:
            edge.times, edge.values = [0.0], [value]
            return True
        stamp = transform_stamped.header.stamp.to_sec()
        times = edge.times
        if not times or stamp > times[-1]:
            times.append(stamp)
            edge.values.append(value)
        elif stamp == times[-1]:
            edge.values[-1] = value
        else:
            i = bisect.bisect_left(times, stamp)
            if i < len(times) and times[i] == stamp:
                edge.values[i] = value
            else:
                times.insert(i, stamp)
                edge.values.insert(i, value)
        # Drop samples older than the cache, keeping at least two.
        if len(times) > 64 and times[-1] - times[0] > 2 * self.cache_time:
            cut = bisect.bisect_left(times, times[-1] - self.cache_time)
            cut = min(cut, len(times) - 2)
            del times[:cut]
            del edge.values[:cut]
        return True

    def frames(self):
        return sorted(set(self._edges) | {e.parent for e in self._edges.values()})

    def _path_to_root(self, frame):
        path = []
        seen = {frame}
        while frame in self._edges:
            edge = self._edges[frame]
            path.append((frame, edge))
            frame = edge.parent
            if frame in seen:  # a loop in a broken tf tree
                break
            seen.add(frame)
        return frame, path

    def ready(self, target, source, stamp):
        """True when every dynamic edge between the frames has a sample at or after stamp."""
        root_s, path_s = self._path_to_root(_strip(source))
        root_t, path_t = self._path_to_root(_strip(target))
        if root_s != root_t:
            return False
        for _, edge in path_s + path_t:
            if not edge.static and edge.times[-1] < stamp:
                return False
        return True

    def _sample(self, child, edge, stamp):
        if edge.static:
            return edge.values[0]
        times = edge.times
        i = bisect.bisect_left(times, stamp)
        if i < len(times) and times[i] == stamp:
            return edge.values[i]
        if i == 0:
            if times[0] - stamp <= self.tolerance:
                return edge.values[0]
            raise TransformError("tf_extrapolation", "%s -> %s: stamp %.3f is %.3f s before the first sample"
                                 % (edge.parent, child, stamp, times[0] - stamp))
        if i == len(times):
            if stamp - times[-1] <= self.tolerance:
                return edge.values[-1]
            raise TransformError("tf_gap", "%s -> %s: no sample since %.3f, %.3f s before the stamp %.3f"
                                 % (edge.parent, child, times[-1], stamp - times[-1], stamp))
        t0, t1 = times[i - 1], times[i]
        if t1 - t0 > self.max_gap:
            # Within the tolerance of one side it is not a gap, just a neighbour.
            if stamp - t0 <= self.tolerance:
                return edge.values[i - 1]
            if t1 - stamp <= self.tolerance:
                return edge.values[i]
            raise TransformError("tf_gap", "%s -> %s: no sample between %.3f and %.3f (gap %.2f s > max %.2f s)"
                                 % (edge.parent, child, t0, t1, t1 - t0, self.max_gap))
        return _interpolate(edge.values[i - 1], edge.values[i], (stamp - t0) / (t1 - t0))

    def lookup(self, target, source, stamp):
        """Transform of `source` in `target` at stamp, as (tx, ty, tz, qx, qy, qz, qw).

        Raises TransformError(reason) with reason tf_unconnected, tf_gap or tf_extrapolation.
        """
        source, target = _strip(source), _strip(target)
        root_s, path_s = self._path_to_root(source)
        root_t, path_t = self._path_to_root(target)
        if root_s != root_t:
            raise TransformError("tf_unconnected", "frame %r is not connected to %r (tree roots %r and %r)"
                                 % (source, target, root_s, root_t))
        # Drop the common tail (edges above the lowest common ancestor).
        while path_s and path_t and path_s[-1][0] == path_t[-1][0]:
            path_s.pop()
            path_t.pop()
        identity = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
        ancestor_source = identity
        for child, edge in reversed(path_s):
            ancestor_source = _compose(ancestor_source, self._sample(child, edge, stamp))
        ancestor_target = identity
        for child, edge in reversed(path_t):
            ancestor_target = _compose(ancestor_target, self._sample(child, edge, stamp))
        return _compose(_inverse(ancestor_target), ancestor_source)
