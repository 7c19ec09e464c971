"""Per-source quotas (issue 27, item 3): live obstacles per source and a token bucket of updates per
source. A flooding source's excess is dropped and counted (in all and per source) while every other
source, and the robot itself, goes on as before. Pure; no wall clock (a fake clock)."""
import logging

from handler_fixtures import GRID, Recorder, U, cells_in, proposal, rect, update
from sharing_msgs.authority import quotas


def far(k, source="robot_9", version=1, stamp=100.0, uuid=None):
    """A one-cell obstacle in slot k: slots are 1 m apart (beyond merge_distance), so none merge."""
    col, row = (k % 20) * 20, (k // 20) * 20
    x, y = GRID.origin_x + col * GRID.resolution, GRID.origin_y + row * GRID.resolution
    return update(uuid or U("%s-%d" % (source[-1], k)), marked=(row * GRID.size_x + col,), version=version,
                  source=source, rectangle=rect(x, y, x + GRID.resolution, y + GRID.resolution), stamp=stamp)


def drop_lines(caplog, reason):
    return [r.getMessage() for r in caplog.records if reason in r.getMessage()]


def test_live_obstacle_quota_drops_a_floods_excess_and_counts_it_per_source(caplog):
    caplog.set_level(logging.INFO)
    r = Recorder(max_obstacles_per_source=3)
    h = r.handler
    accepted = [h.on_external(far(k)) for k in range(8)]
    assert accepted == [True] * 3 + [False] * 5
    assert h.live_per_source()["robot_9"] == 3
    counters = h.counters
    assert counters["dropped_source_quota"] == 5
    assert h.source_counters() == {"dropped_source_quota.robot_9": 5}
    # another source's new obstacle, an update of one robot_9 holds, and this robot's own proposal still go
    assert h.on_external(far(20, source="robot_2"))
    assert h.on_external(far(0, version=2))
    assert h.on_proposal(proposal(cells=cells_in(rect(0, 0, 0.05, 0.05), 1), rectangle=rect(0, 0, 0.05, 0.05))) is not None
    assert len(h) == 5
    # one line a field engineer can act on (robot, count, limit), not one per message
    lines = drop_lines(caplog, "source_quota")
    assert len(lines) == 1
    assert "robot_9" in lines[0] and "max_obstacles_per_source 3" in lines[0] and "3 live obstacles" in lines[0]


def test_quota_frees_when_the_sources_obstacles_leave():
    r = Recorder(max_obstacles_per_source=2, duration=60)
    h = r.handler
    assert h.on_external(far(0)) and h.on_external(far(1))
    assert not h.on_external(far(2))
    r.clock.now += 61           # both expire
    assert len(h.expire()) == 2
    assert h.live_per_source() == {}
    assert h.on_external(far(3, stamp=r.clock.now))


def test_the_robot_itself_is_not_limited():
    """Peers give a restarted robot its own obstacles back (source = its own name): never refused."""
    r = Recorder(max_obstacles_per_source=1, source_update_rate=1.0, source_update_burst=1)
    h = r.handler
    assert all(h.on_external(far(k, source="robot_0")) for k in range(5))
    assert h.counters["dropped_source_quota"] == h.counters["dropped_source_rate"] == 0


def test_update_rate_per_source_drops_the_excess_and_refills(caplog):
    caplog.set_level(logging.INFO)
    r = Recorder(source_update_rate=2.0, source_update_burst=3)
    h = r.handler
    # five messages from robot_9 at one instant: the burst goes, the rest is dropped
    assert [h.on_external(far(k)) for k in range(5)] == [True] * 3 + [False] * 2
    assert h.counters["dropped_source_rate"] == 2
    assert h.source_counters() == {"dropped_source_rate.robot_9": 2}
    # another source is not held back by robot_9's empty bucket
    assert h.on_external(far(10, source="robot_2"))
    # one second later robot_9 has two tokens again
    r.clock.now += 1.0
    assert [h.on_external(far(k, stamp=r.clock.now)) for k in range(20, 23)] == [True, True, False]
    assert h.counters["dropped_source_rate"] == 3
    lines = drop_lines(caplog, "source_rate")
    assert len(lines) == 1 and "robot_9" in lines[0] and "source_update_rate 2/s" in lines[0]


def test_drop_lines_are_rate_limited_and_summed():
    class Log:
        def __init__(self):
            self.lines = []

        def warning(self, fmt, *args):
            self.lines.append(fmt % args)

    log = Log()
    report = quotas.DropReport("robot_0", interval=10.0, log=log)
    for i in range(100):
        report.drop("robot_9", "source_quota", 100.0 + i * 0.01, "hint")
    assert len(log.lines) == 1                       # the first at once
    report.flush(105.0)
    assert len(log.lines) == 1                       # not yet due
    report.flush(110.0)
    assert len(log.lines) == 2 and "dropped 99 message(s)" in log.lines[1] and "100 in all" in log.lines[1]
    report.flush(130.0)
    assert len(log.lines) == 2                       # nothing new: silent
    assert report.counters() == {"dropped_source_quota.robot_9": 100}


def test_token_buckets_are_per_key_and_bounded():
    buckets = quotas.TokenBuckets(rate=1.0, burst=2, max_keys=3)
    assert [buckets.allow("a", 0.0) for _ in range(3)] == [True, True, False]
    assert buckets.allow("b", 0.0)
    assert buckets.allow("a", 1.0) and not buckets.allow("a", 1.0)
    for key in "cdef":
        buckets.allow(key, 2.0)
    assert len(buckets._buckets) == 3
