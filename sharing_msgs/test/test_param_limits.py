"""Every numeric range of PeerPolicy's own settings, just inside and just outside: a limit moved by one step
(``<=`` for ``<``, a bound off by one) turns one of these red. (max_version_step's least value is tested in
test_authority_versions.py; the caps applied to messages in test_authority_limits.py.)"""
import pytest

from sharing_msgs.authority import PeerPolicy


def check(name, value, accepted, message):
    """A PeerPolicy with ``name`` = ``value`` is taken, or refused with ``message``."""
    fields = dict({"max_extent": 10.0, "max_lifetime": 60}, **{name: value})
    if accepted:
        assert getattr(PeerPolicy(**fields), name) == value
    else:
        with pytest.raises(ValueError) as info:
            PeerPolicy(**fields)
        assert str(info.value) == message % (value,)


@pytest.mark.parametrize("value,accepted", [(None, True), (0, True), (-0.001, False),
                                            (3600, True), (3600.001, False)])
def test_max_clock_skew_is_none_or_0_to_3600_s(value, accepted):
    """A skew beyond an hour lets a message captured an hour ago be replayed (issue 27)."""
    check("max_clock_skew", value, accepted, "max_clock_skew %r must be None or 0..3600 s")


@pytest.mark.parametrize("value,accepted", [(0, True), (-0.001, False), (1000, True), (1000.001, False)])
def test_max_sensor_reach_is_0_to_1000_m(value, accepted):
    """0: robots' obstacles bounded by max_extent alone; no sensor reaches a kilometre (issue 43)."""
    check("max_sensor_reach", value, accepted, "max_sensor_reach %r must be 0..1000 m")


@pytest.mark.parametrize("value,accepted", [(0.001, True), (0, False), (1e6 - 0.001, True), (1e6, False)])
def test_max_extent_is_above_0_and_below_1e6_m(value, accepted):
    check("max_extent", value, accepted, "max_obstacle_extent %r must be a positive number of metres")


@pytest.mark.parametrize("name,value,accepted", [("max_obstacle_cells", 0, True), ("max_obstacle_cells", -1, False),
                                                 ("max_lifetime", 1, True), ("max_lifetime", 0, False)])
def test_integer_caps_at_their_lower_limit(name, value, accepted):
    """0 cells: the cells of a max_extent square; a lifetime of 0 s would cut every deadline to nothing."""
    check(name, value, accepted, name + " %r must be an integer >= " + str(1 if name == "max_lifetime" else 0))
