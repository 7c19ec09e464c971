"""fleet.launch refuses bad arguments with the argument's name, and builds 1..10 robots."""
import os
import re
import socket
import subprocess

import pytest

ENV = dict(os.environ, ROS_IP="127.0.0.1", ROS_HOSTNAME="127.0.0.1")


def nodes(*args):
    proc = subprocess.run(["roslaunch", "--nodes", "fleet_launch", "fleet.launch"] + list(args),
                          capture_output=True, text=True, env=ENV, timeout=120)
    return proc.returncode, proc.stdout + proc.stderr


@pytest.mark.parametrize("arg, name", [
    ("robots:=0", "robots_must_be_an_integer_from_1_to_10"),
    ("robots:=11", "robots_must_be_an_integer_from_1_to_10"),
    ("robots:=two", "robots_must_be_an_integer_from_1_to_10"),
    ("robots:=-1", "robots_must_be_an_integer_from_1_to_10"),
    ("obstacle_duration:=0", "obstacle_duration_must_be_at_least_1_second"),
    ("localisation_error:=-0.1", "localisation_error_must_be_non_negative"),
    ("localisation_error_yaw:=-1", "localisation_error_must_be_non_negative"),
])
def test_bad_argument_is_refused_with_its_name(arg, name):
    rc, out = nodes(arg)
    assert rc != 0, out
    assert name in out, out


@pytest.mark.parametrize("robots", [1, 2, 10])
def test_each_robot_gets_its_namespace(robots):
    rc, out = nodes("robots:=%d" % robots)
    assert rc == 0, out
    listed = set(out.split())
    for i in range(robots):
        for node in ("move_base", "sharing_handler", "coaty_bridge"):
            assert "/robot_%d/%s" % (i, node) in listed, out
    assert "/robot_%d/move_base" % robots not in listed
    assert {"/fleet_sim", "/map_server", "/fleet_broker"} <= listed


def test_sharing_off_runs_no_handler_bridge_or_broker():
    rc, out = nodes("robots:=2", "sharing:=false")
    assert rc == 0, out
    assert "/robot_1/move_base" in out
    assert not re.search(r"sharing_handler|coaty_bridge|fleet_broker", out), out


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_missing_world_stops_the_launch_naming_the_file(tmp_path):
    port = free_port()
    env = dict(ENV, ROS_MASTER_URI="http://127.0.0.1:%d" % port, ROS_HOME=str(tmp_path))
    world = str(tmp_path / "no_such.world")
    proc = subprocess.run(["roslaunch", "-p", str(port), "fleet_launch", "fleet.launch", "world:=" + world,
                           "output:=screen"], capture_output=True, text=True, env=env, timeout=120)
    out = proc.stdout + proc.stderr
    assert re.search(r"fleet_sim cannot start: .*no_such\.world: cannot read world file", out), out
    assert re.search(r"REQUIRED process \[fleet_sim-\d+\] has died", out), out
