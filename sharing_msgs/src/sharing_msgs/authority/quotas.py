"""Per-source quotas (issue 27, item 3): what one source may cost a receiver. Pure Python, no ROS.

A peer sending valid obstacles can still flood: 5,000 new obstacles made every robot hold 5,000
more and delayed everyone else's for minutes. So each receiver bounds, per source:

- live obstacles: a source may hold at most ``max_obstacles`` on this robot; a new obstacle
  beyond that is dropped (``source_quota``); updates of the ones it holds still apply;
- updates per second: a token bucket of ``rate`` per s and ``burst`` (``source_rate``).

Buckets and counts are per source, so one source's flood empties only its own bucket: the robot's
own obstacles, a master control's and every other peer's go on as before. ``TokenBuckets`` is
also what the Coaty bridge uses per MQTT sourceId, before a payload is parsed.
"""
import collections
import logging

_log = logging.getLogger(__name__)

#: s between two log lines about one (source, reason): the first drop is logged at once, later
#: ones are summed into one line per interval.
LOG_INTERVAL = 10.0

#: sources whose drops are kept apart for /diagnostics (the rest are summed in the totals only)
MAX_SOURCES_REPORTED = 64


class TokenBuckets:
    """One token bucket per key: ``rate`` tokens per s up to ``burst``. Keys quiet long enough to
    have a full bucket again are forgotten once more than ``max_keys`` are kept (oldest first)."""

    def __init__(self, rate, burst, max_keys=4096):
        if isinstance(rate, bool) or not isinstance(rate, (int, float)) or not 0 < rate < 1e9:
            raise ValueError("rate %r must be a positive number per second" % (rate,))
        if isinstance(burst, bool) or not isinstance(burst, int) or burst < 1:
            raise ValueError("burst %r must be an integer >= 1" % (burst,))
        self.rate, self.burst, self.max_keys = float(rate), int(burst), int(max_keys)
        self._buckets = collections.OrderedDict()   # key -> [tokens, last refill]

    def allow(self, key, now, cost=1.0):
        """True (and a token taken) when `key` may send one more now."""
        bucket = self._buckets.get(key)
        if bucket is None:
            bucket = self._buckets[key] = [float(self.burst), now]
            while len(self._buckets) > self.max_keys:
                self._buckets.popitem(last=False)
        else:
            self._buckets.move_to_end(key)
            bucket[0] = min(float(self.burst), bucket[0] + max(0.0, now - bucket[1]) * self.rate)
            bucket[1] = now
        if bucket[0] >= cost:
            bucket[0] -= cost
            return True
        return False


class DropReport:
    """Counts drops per (source, reason) and writes a log line a field engineer can act on, at
    most one per (source, reason) every ``interval`` s: the first at once, then the sum since."""

    def __init__(self, robot_name, interval=LOG_INTERVAL, log=_log):
        self.robot_name = robot_name
        self.interval = interval
        self._log = log
        self.by_source = collections.OrderedDict()   # source -> Counter(reason -> n)
        self._pending = {}     # (source, reason) -> [n not logged yet, last log time, hint]

    def drop(self, source, reason, now, hint):
        counts = self.by_source.get(source)
        if counts is None:
            counts = self.by_source[source] = collections.Counter()
            while len(self.by_source) > MAX_SOURCES_REPORTED:
                self.by_source.popitem(last=False)
        counts[reason] += 1
        state = self._pending.get((source, reason))
        if state is None:
            self._pending[(source, reason)] = [0, now, hint]
            self._write(source, reason, 1, hint, first=True)
            return
        state[0] += 1
        state[2] = hint
        if now - state[1] >= self.interval:
            self.flush_one(source, reason, now)

    def flush(self, now):
        """Writes the lines due (called on every tick, so a flood that stopped is still reported)."""
        for (source, reason), state in list(self._pending.items()):
            if state[0] and now - state[1] >= self.interval:
                self.flush_one(source, reason, now)

    def flush_one(self, source, reason, now):
        state = self._pending[(source, reason)]
        if state[0]:
            self._write(source, reason, state[0], state[2], first=False)
        state[0], state[1] = 0, now

    def _write(self, source, reason, n, hint, first):
        total = self.by_source.get(source, {}).get(reason, n)
        self._log.warning("%s: %s %d message(s) from %r (%s; %d in all from it): %s%s",
                          self.robot_name, "dropping" if first else "dropped", n, source, reason, total, hint,
                          "" if first else " (one line per %g s)" % self.interval)

    def counters(self):
        """{"dropped_<reason>.<source>": n} for /diagnostics."""
        return {"dropped_%s.%s" % (reason, source): n
                for source, counts in self.by_source.items() for reason, n in counts.items()}


class SourceQuotas:
    """The handler's per-source limits: live obstacles and a token bucket of updates per source.
    ``exempt``: sources never limited (the robot itself: peers give it its own obstacles back
    after a restart, and what it shares comes from its own layer)."""

    def __init__(self, max_obstacles, rate, burst, exempt=()):
        if isinstance(max_obstacles, bool) or not isinstance(max_obstacles, int) or max_obstacles < 1:
            raise ValueError("max_obstacles_per_source %r must be an integer >= 1" % (max_obstacles,))
        self.max_obstacles = max_obstacles
        self.buckets = TokenBuckets(rate, burst)
        self.exempt = frozenset(exempt)
        self.live = collections.Counter()    # source -> obstacles held that it created here

    def allow_update(self, source, now):
        return source in self.exempt or self.buckets.allow(source, now)

    def allow_new(self, source):
        return source in self.exempt or self.live[source] < self.max_obstacles

    def added(self, owner):
        self.live[owner] += 1

    def removed(self, owner):
        n = self.live[owner] - 1
        if n > 0:
            self.live[owner] = n
        else:
            del self.live[owner]
