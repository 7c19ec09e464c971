"""The console node's numeric parameter ranges (node.settings, pure), just inside and just outside: a limit
moved by one (``<=`` for ``<``, a bound off by one) turns one of these red."""
import pytest

from fleet_console import node


def check(name, value, accepted, why):
    """The console's settings with ``name`` = ``value`` (as if from the command line) are taken, or refused
    naming it, its value and ``why``."""
    args = node.parse_args([])
    setattr(args, name, value)
    if accepted:
        return node.settings(args, None)[name]
    with pytest.raises(ValueError) as info:
        node.settings(args, None)
    assert str(info.value) == "parameter %s = %r: %s" % (name, value, why)
    return None


@pytest.mark.parametrize("value,accepted", [(0, True), (-1, False), (65535, True), (65536, False)])
def test_port_is_0_to_65535(value, accepted):
    """0: a free port the node prints; a TCP port has 16 bits."""
    assert check("port", value, accepted, "must be 0..65535") == (value if accepted else None)


@pytest.mark.parametrize("value,accepted", [(1, True), (0.999, False)])
def test_obstacle_duration_is_at_least_1_s(value, accepted):
    """The lease a confirmation or an added obstacle asks for, in whole seconds (rounded up): 1 s is the least."""
    assert check("obstacle_duration", value, accepted, "seconds, at least 1") == (1 if accepted else None)
