"""Every numeric limit of the rules of authority, just inside and just outside: a limit loosened or
tightened (a doubled window, a cap on the wrong side, a bucket without its cap) turns one of these red."""
import pytest

from sharing_msgs.authority import AuthorityError, PeerPolicy, TokenBuckets
from sharing_msgs.authority.policy import EXTENT_SLACK, single_robot_extent


class Rect:
    def __init__(self, min_x, min_y, max_x, max_y):
        self.min_x, self.min_y, self.max_x, self.max_y = min_x, min_y, max_x, max_y


class Grid:
    resolution = 0.05


def reason(call):
    try:
        call()
    except AuthorityError as err:
        return err.reason
    return None


# ------------------------------------------------------------------------------------------ stamps

NOW = 1700000000.0


def test_a_stamp_ahead_by_just_under_max_clock_skew_passes_and_just_over_is_future():
    policy = PeerPolicy(max_extent=10.0, max_lifetime=60, max_clock_skew=5.0)
    assert reason(lambda: policy.check_stamp(NOW + 4.99, NOW)) is None
    assert reason(lambda: policy.check_stamp(NOW + 5.01, NOW)) == "future_stamp"


def test_a_stamp_older_than_lifetime_plus_skew_is_stale_just_outside_only():
    policy = PeerPolicy(max_extent=10.0, max_lifetime=60, max_clock_skew=5.0)
    assert policy.max_message_age == 65.0
    assert reason(lambda: policy.check_stamp(NOW - 64.99, NOW)) is None
    assert reason(lambda: policy.check_stamp(NOW - 65.01, NOW)) == "stale_stamp"


def test_tombstones_last_the_lifetime_plus_twice_the_skew():
    assert PeerPolicy(max_extent=10.0, max_lifetime=60, max_clock_skew=5.0).tombstone_time == 70.0
    assert PeerPolicy(max_extent=10.0, max_lifetime=60).tombstone_time == 60


# ------------------------------------------------------------------------------------------ caps

@pytest.mark.parametrize("long_side", ["x", "y"])
def test_the_extent_cap_holds_on_the_longer_side_just_inside_and_just_outside(long_side):
    policy = PeerPolicy(max_extent=10.0, max_lifetime=60)

    def rect(length):
        return Rect(0.0, 0.0, length, 0.5) if long_side == "x" else Rect(0.0, 0.0, 0.5, length)
    assert reason(lambda: policy.check_extent(rect(9.99))) is None
    assert reason(lambda: policy.check_extent(rect(10.01))) == "oversized_rectangle"
    assert policy.fits(rect(9.99), 1, Grid)
    assert not policy.fits(rect(10.01), 1, Grid)


def test_a_robots_obstacle_is_capped_by_what_its_sensor_reaches():
    policy = PeerPolicy(max_extent=50.0, max_lifetime=60, max_sensor_reach=5.0)
    cap = single_robot_extent(5.0)
    assert cap == 2 * (5.0 + EXTENT_SLACK) < 50.0
    assert reason(lambda: policy.check_extent(Rect(0, 0, cap - 0.01, 1), source="robot_1")) is None
    assert reason(lambda: policy.check_extent(Rect(0, 0, cap + 0.01, 1), source="robot_1")) == "oversized_rectangle"


def test_the_cell_cap_just_inside_and_just_outside():
    policy = PeerPolicy(max_extent=10.0, max_lifetime=60)
    cap = (200 + 2) ** 2   # a 10 m square on a 5 cm grid, one cell of margin per side
    assert policy.cell_cap(Grid) == cap
    assert reason(lambda: policy.check_cells(cap, Grid)) is None
    assert reason(lambda: policy.check_cells(cap + 1, Grid)) == "too_many_obstacle_cells"
    assert policy.fits(Rect(0, 0, 1, 1), cap, Grid) and not policy.fits(Rect(0, 0, 1, 1), cap + 1, Grid)
    explicit = PeerPolicy(max_extent=10.0, max_lifetime=60, max_obstacle_cells=100)
    assert reason(lambda: explicit.check_cells(100, Grid)) is None
    assert reason(lambda: explicit.check_cells(101, Grid)) == "too_many_obstacle_cells"


def test_a_version_step_just_inside_and_just_outside_max_version_step():
    policy = PeerPolicy(max_extent=10.0, max_lifetime=60, max_version_step=1000)
    assert reason(lambda: policy.check_version(1007, 7)) is None
    assert reason(lambda: policy.check_version(1008, 7)) == "implausible_version"


def test_a_deadline_is_cut_to_the_lifetime():
    policy = PeerPolicy(max_extent=10.0, max_lifetime=60)
    assert policy.cap_deadline(59) == 59 and policy.cap_deadline(60) == 60 and policy.cap_deadline(61) == 60


# ------------------------------------------------------------------------------------------ rates

def test_after_an_hours_quiet_the_bucket_holds_its_burst_and_not_one_more():
    """The handler's defaults (100 per s, burst 2000): a source quiet for an hour sends 2000 at once, not the
    360,000 an uncapped refill would allow."""
    buckets = TokenBuckets(rate=100.0, burst=2000)
    assert buckets.allow("robot_1", 0.0)
    now = 3600.0
    taken = 0
    while taken < 5000 and buckets.allow("robot_1", now):
        taken += 1
    assert taken == 2000


def test_the_bucket_refills_at_its_rate_just_inside_and_just_outside():
    buckets = TokenBuckets(rate=100.0, burst=5)
    assert all(buckets.allow("a", 0.0) for _ in range(5))
    assert not buckets.allow("a", 0.0)
    assert not buckets.allow("a", 0.009)          # 0.9 of a token
    assert buckets.allow("a", 0.0101)             # 1.01 tokens since the drain, 0.9 of them kept
    assert not buckets.allow("a", 0.0101)
    assert all(buckets.allow("b", 0.0) for _ in range(5)), "another key has its own bucket"
