"""Every numeric range of the handler's parameters (HandlerParams), just inside and just outside: a limit moved by
one step (``<=`` for ``<``, a bound off by one) turns one of these red. Pure: no ROS."""
import pytest

from sharing_handler_py.errors import InvalidParameterError
from sharing_handler_py.validation import HandlerParams
from sharing_msgs.authority import MIN_VERSION_STEP


def check(name, value, accepted):
    """HandlerParams of robot_0 with ``name`` = ``value`` is taken, or refused naming it and its value."""
    if accepted:
        assert getattr(HandlerParams(robot_name="robot_0", **{name: value}), name) == value
    else:
        with pytest.raises(InvalidParameterError) as info:
            HandlerParams(robot_name="robot_0", **{name: value})
        assert str(info.value).startswith("~%s = %r: " % (name, value)), str(info.value)


@pytest.mark.parametrize("value,accepted", [(1.0, True), (0.999, False),
                                            (2.0 ** 32 - 1, True), (2.0 ** 32 - 1 + 0.001, False)])
def test_obstacle_duration_is_1_s_to_the_largest_message_deadline(value, accepted):
    """The lease goes out as the message's uint32 deadline: a longer one cannot be sent."""
    check("obstacle_duration", value, accepted)


@pytest.mark.parametrize("value,accepted", [(0.001, True), (0, False), (1000.0, True), (1000.001, False)])
def test_expiry_rate_is_above_0_to_1000_hz(value, accepted):
    """0 Hz would never expire anything; above 1000 Hz the timer is all the node does."""
    check("expiry_rate", value, accepted)


@pytest.mark.parametrize("name,value,accepted", [
    ("max_cells_per_message", 1, True), ("max_cells_per_message", 0, False),
    ("max_obstacle_cells", 0, True), ("max_obstacle_cells", -1, False),   # 0: a max_obstacle_extent square
    ("max_version_step", MIN_VERSION_STEP, True), ("max_version_step", MIN_VERSION_STEP - 1, False),
    ("max_obstacles_per_source", 1, True), ("max_obstacles_per_source", 0, False),
    ("source_update_burst", 1, True), ("source_update_burst", 0, False),
    ("source_queue_size", 1, True), ("source_queue_size", 0, False),
])
def test_integer_parameters_at_their_lower_limit(name, value, accepted):
    """A cap of 0 (a step below what an operator's action needs) would drop everything (or an operator's
    removal)."""
    check(name, value, accepted)


@pytest.mark.parametrize("value,accepted", [(0.001, True), (0, False), (1e6 - 0.001, True), (1e6, False)])
def test_max_obstacle_extent_is_above_0_and_below_1e6_m(value, accepted):
    check("max_obstacle_extent", value, accepted)


@pytest.mark.parametrize("value,accepted", [(0.0, True), (-0.001, False), (1e6 - 0.001, True), (1e6, False)])
def test_merge_distance_is_0_to_below_1e6_m(value, accepted):
    """0 merges only what overlaps; a negative distance would merge nothing, not even the same obstacle."""
    check("merge_distance", value, accepted)


@pytest.mark.parametrize("value,accepted", [
    (-1, True), (-1.001, False), (-0.999, False),          # -1: stamps not checked
    (0, True), (-0.001, False), (3600, True), (3600.001, False),
])
def test_max_clock_skew_is_minus_1_or_0_to_3600_s(value, accepted):
    """A skew beyond an hour lets a message captured an hour ago be replayed (issue 27)."""
    check("max_clock_skew", value, accepted)


@pytest.mark.parametrize("value,accepted", [(0.001, True), (0, False), (1e9 - 0.001, True), (1e9, False)])
def test_source_update_rate_is_above_0_and_below_1e9_per_s(value, accepted):
    check("source_update_rate", value, accepted)


@pytest.mark.parametrize("value,accepted", [(0.0, True), (-0.001, False), (1000.0, True), (1000.001, False)])
def test_max_sensor_reach_is_0_to_1000_m(value, accepted):
    """The same range as sharing_msgs' PeerPolicy, which the handler passes it to (issue 43)."""
    check("max_sensor_reach", value, accepted)


@pytest.mark.parametrize("value,accepted", [(0.001, True), (0, False), (1.0, True), (1.001, False)])
def test_list_cost_share_is_above_0_to_1(value, accepted):
    """A share of time: 0 would never rebuild the latched list, more than all of it is no cap."""
    check("list_cost_share", value, accepted)
