"""fleet_nav's fleet-robot exclusion parameters (issue 12, part 5): read from sharing/ or
sharing_layer/ like the other layer parameters, validated, and handed to the layer."""
import numpy as np
import pytest

pytest.importorskip("fleet_nav.nav_core")

from sharing_layer_cpp import core  # noqa: E402
from fleet_nav.costmap import GlobalCostmap  # noqa: E402
from fleet_nav.errors import ParameterError  # noqa: E402
from fleet_nav.params import NavParams  # noqa: E402


def test_defaults_and_both_namespaces():
    params, unused = NavParams.from_dict({})
    assert (params.robot_exclusion_margin, params.robot_timeout) == (0.2, 3.0)
    params, unused = NavParams.from_dict({"sharing": {"robot_exclusion_margin": 0.35, "robot_timeout": 5}})
    assert (params.robot_exclusion_margin, params.robot_timeout) == (0.35, 5.0) and unused == []
    params, _ = NavParams.from_dict({"sharing_layer": {"robot_exclusion_margin": 0.0, "robot_timeout": 0.0}})
    assert (params.robot_exclusion_margin, params.robot_timeout) == (0.0, 0.0)
    assert params.robot_exclusion_trail == 1.0
    for trail in (0.0, 10.0):  # the layer's limits, inclusive
        params, _ = NavParams.from_dict({"sharing": {"robot_exclusion_trail": trail}})
        assert params.robot_exclusion_trail == trail


@pytest.mark.parametrize("key, value", [("robot_exclusion_margin", -0.1), ("robot_exclusion_margin", "wide"),
                                        ("robot_exclusion_margin", float("nan")), ("robot_exclusion_margin", 80.0),
                                        ("robot_timeout", -1.0), ("robot_timeout", float("inf")),
                                        ("robot_timeout", True), ("robot_exclusion_trail", -0.01),
                                        ("robot_exclusion_trail", 10.01), ("robot_exclusion_trail", float("nan"))])
def test_bad_values_name_the_parameter(key, value):
    with pytest.raises(ParameterError, match=key):
        NavParams.from_dict({"sharing": {key: value}})


def test_the_layer_gets_them_and_leaves_a_fleet_robot_out():
    params, _ = NavParams.from_dict({"sharing": {"robot_exclusion_margin": 0.3, "robot_timeout": 4.0,
                                                 "robot_exclusion_trail": 0.5}, "robot_radius": 0.2})
    occ = np.zeros((120, 200), dtype=np.int8)
    geometry = core.GridGeometry(0.05, 0.0, 0.0, 200, 120)
    cm = GlobalCostmap(geometry, occ.reshape(-1), params, core.LayerParams(robot_name="robot_0"))
    robots = cm.layer.fleet_robots
    assert (robots.margin, robots.timeout, robots.trail) == (0.3, 4.0, 0.5)
    square = np.array([[4.0, 3.0], [4.6, 3.0], [4.6, 3.6], [4.0, 3.6]])
    robots.update("robot_1", square, 1.0)
    # the scan sees robot_1's body: nothing of it becomes shareable
    body = [(x, y, 0.2) for x in np.arange(4.0, 4.6, 0.02) for y in (3.0,)]
    cm.layer.process_scan((4.3, 1.5, 0.2), np.array(body), 1.0)
    assert len(cm.layer.shareable_cells()) == 0
    robots.forget("robot_1")
    cm.layer.process_scan((4.3, 1.5, 0.2), np.array(body), 1.1)
    assert len(cm.layer.shareable_cells()) > 0, "the body is shareable once robot_1 is unknown: the test can fail"
