"""fleet.launch refuses bad arguments with the argument's name, builds 1..10 robots, and picks the
world, map and goals of the layout it is given; bench_fleet refuses a bad layout likewise."""
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
    ("layout:=nowhere", "layout_must_be_facility_deadend_or_corridors"),
    ("layout:=Facility", "layout_must_be_facility_deadend_or_corridors"),
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


def params(*args):
    proc = subprocess.run(["roslaunch", "--dump-params", "fleet_launch", "fleet.launch"] + list(args),
                          capture_output=True, text=True, env=ENV, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    out = {}
    for line in proc.stdout.splitlines():
        key, sep, value = line.partition(": ")
        if sep:
            out[key.strip()] = value.strip()
    return out


@pytest.mark.parametrize("layout, robots, goals", [
    (None, 2, "goals.yaml"),
    ("facility", 5, "goals.yaml"),
    ("deadend", 2, "deadend_goals.yaml"),
    ("deadend", 10, "deadend_goals.yaml"),
    ("corridors", 2, "corridors_goals.yaml"),
])
def test_layout_selects_world_map_and_goals(layout, robots, goals):
    p = params("robots:=%d" % robots, *(["layout:=" + layout] if layout else []))
    name = layout or "facility"
    assert os.path.basename(p["/fleet_sim/world"]) == "%s_%d.world" % (name, robots), p
    assert os.path.basename(p["/fleet_sim/map_yaml"]) == name + ".yaml", p
    assert os.path.basename(p["/fleet/goals"]) == goals, p
    for key in ("/fleet_sim/world", "/fleet_sim/map_yaml", "/fleet/goals"):
        assert os.path.isfile(p[key]), p[key]


@pytest.mark.parametrize("args, message", [
    (["--layout", "nowhere"], "--layout must be one of facility, deadend, corridors, got 'nowhere'"),
    (["--robots", "11"], "robots must be 1..10"),
    (["--seed", "x"], "invalid int value: 'x'"),
    (["--obstacle-duration", "0"], "--obstacle-duration must be at least 1 s"),
    (["--time-limit", "-1"], "--time-limit at least 0"),
    (["--nav-params", "/nonexistent/nav.yaml"], "--nav-params: /nonexistent/nav.yaml is not a file"),
    (["--summarize", "/nonexistent/bench"], "--summarize: /nonexistent/bench is not a folder"),
    (["--summarize", os.path.dirname(os.path.abspath(__file__))], "no bench results"),
])
def test_bench_fleet_refuses_bad_options_before_starting_anything(args, message):
    script = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scripts", "bench_fleet")
    proc = subprocess.run(["/usr/bin/python3", script] + args, capture_output=True, text=True, env=ENV, timeout=60)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert message in proc.stderr, proc.stderr
    assert "bench_fleet_" not in proc.stdout + proc.stderr      # no run (log folder) was started


def test_rviz_true_adds_rviz_on_the_fleet_config():
    rc, out = nodes("rviz:=true")
    assert rc == 0 and "/rviz" in out.split(), out
    p = subprocess.run(["roslaunch", "--args", "/rviz", "fleet_launch", "fleet.launch", "rviz:=true"],
                       capture_output=True, text=True, env=ENV, timeout=120)
    assert re.search(r"rviz -d \S*/config/fleet\.rviz", p.stdout), p.stdout + p.stderr


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


def test_fleet_robot_exclusion_is_wired():
    """Each bridge advertises the footprint fleet_nav publishes (issue 12, part 5: robots are never
    shared); the layer keeps its defaults (robot_exclusion_margin 0.2 m, robot_timeout 3 s)."""
    proc = subprocess.run(["roslaunch", "--dump-params", "fleet_launch", "fleet.launch", "robots:=2"],
                          capture_output=True, text=True, env=ENV, timeout=120)
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    for i in range(2):
        assert "/robot_%d/coaty_bridge/footprint_topic: move_base/global_costmap/footprint" % i in out, out
        assert "/robot_%d/coaty_bridge/robot_timeout: 3.0" % i in out
        assert "robot_exclusion_margin" not in out, "the fleet launch should not override the layer's defaults"
