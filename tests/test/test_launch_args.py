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


@pytest.mark.parametrize("arg, message", [
    ("robots:=0", "robots:=0: robots must be a whole number from 1 to 10"),
    ("robots:=11", "robots:=11: robots must be a whole number from 1 to 10"),
    ("robots:=two", "robots:=two: robots must be a whole number from 1 to 10"),
    ("robots:=-1", "robots:=-1: robots must be a whole number from 1 to 10"),
    ("obstacle_duration:=0", "obstacle_duration:=0: obstacle_duration must be a number of seconds, at least 1"),
    ("obstacle_duration:=0.99", "obstacle_duration:=0.99: obstacle_duration must be a number of seconds, at least 1"),
    ("obstacle_duration:=long", "obstacle_duration:=long: obstacle_duration must be a number of seconds, at least 1"),
    ("localisation_error:=-0.1", "localisation_error:=-0.1, localisation_error_yaw:=0.0: both must be numbers, at least 0"),
    ("localisation_error_yaw:=-1", "localisation_error:=0.0, localisation_error_yaw:=-1: both must be numbers, at least 0"),
    ("localisation_error:=some", "localisation_error:=some, localisation_error_yaw:=0.0: both must be numbers, at least 0"),
    ("layout:=nowhere", "layout:=nowhere: layout must be facility, deadend or corridors"),
    ("layout:=Facility", "layout:=Facility: layout must be facility, deadend or corridors"),
])
def test_bad_argument_is_refused_naming_it_its_value_and_what_it_must_be(arg, message):
    rc, out = nodes(arg)
    assert rc != 0, out
    assert "Invalid <arg> tag: " + message in out, out
    assert "is not defined" not in out and "could not convert" not in out, out


@pytest.mark.parametrize("arg", ["robots:=1", "robots:=10", "obstacle_duration:=1", "obstacle_duration:=1.5",
                                 "localisation_error:=0", "localisation_error_yaw:=0.05"])
def test_arguments_at_their_limits_are_taken(arg):
    rc, out = nodes(arg)
    assert rc == 0, out


@pytest.mark.parametrize("launch", ["fleet.launch", "move_base_fleet.launch"])
def test_every_argument_is_documented_and_layout_names_every_layout(launch):
    """roslaunch --ros-args lists each argument with its doc; none may read "undocumented"."""
    proc = subprocess.run(["roslaunch", "--ros-args", "fleet_launch", launch], capture_output=True, text=True,
                          env=ENV, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    listed = dict(re.findall(r"^  (\w+) \(default [^)]*\): (.*)$", proc.stdout, flags=re.M))
    # roslaunch lists an argument whose default is "" under "Required Arguments": it is optional all the same,
    # and its doc must say what empty means
    blank = dict(re.findall(r"^  (\w+): (.*)$", proc.stdout.split("Optional Arguments:")[0], flags=re.M))
    defaults = launch_defaults_of(launch)
    for name, doc in blank.items():
        assert defaults.get(name) == "", "%s: %s has no default (a launch must start without arguments)" % (launch, name)
        assert "empty" in doc, "%s: %s's doc does not say what its empty default means: %s" % (launch, name, doc)
    listed.update(blank)
    declared = {a for a in launch_args_of(launch) if not a.startswith("_")}
    assert set(listed) == declared, proc.stdout
    undocumented = sorted(name for name, doc in listed.items() if doc.strip() == "undocumented")
    assert not undocumented, "%s: arguments without doc: %s" % (launch, undocumented)
    for layout in ("facility", "deadend", "corridors"):
        assert layout in listed["layout"], listed["layout"]


def launch_defaults_of(launch):
    import xml.etree.ElementTree as ET
    import rospkg
    path = os.path.join(rospkg.RosPack().get_path("fleet_launch"), "launch", launch)
    return {a.get("name"): a.get("default") for a in ET.parse(path).getroot().findall("arg")}


def launch_args_of(launch):
    import xml.etree.ElementTree as ET
    import rospkg
    path = os.path.join(rospkg.RosPack().get_path("fleet_launch"), "launch", launch)
    return [a.get("name") for a in ET.parse(path).getroot().findall("arg")]   # the launch's own, not those it passes on


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
    (["--layout", "nowhere"], "--layout must be one of facility, deadend, corridors or all, got 'nowhere'"),
    (["--robots", "11"], "robots must be 1..10"),
    (["--seed", "x"], "invalid int value: 'x'"),
    (["--obstacle-duration", "0"], "--obstacle-duration must be at least 1 s"),
    (["--time-limit", "-1"], "--time-limit at least 0"),
    (["--speedup", "0"], "'0': the factor must be a number above 0"),
    (["--table", "/nonexistent/fleet.md"], "--table /nonexistent/fleet.md: its folder does not exist"),
    (["--chart", "/nonexistent/fleet.png"], "--chart /nonexistent/fleet.png: its folder does not exist"),
    (["--speedup", "10:x"], "'10:x' is not a speedup"),
    (["--speedup", "10:0.5", "10:1"], "--speedup names an N (or the bare FACTOR) twice"),
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


@pytest.mark.parametrize("robots, world_robots, refused", [(2, 2, False), (3, 2, True)])
def test_a_world_with_fewer_robots_than_asked_for_stops_the_launch_naming_both(tmp_path, robots, world_robots,
                                                                              refused):
    """robots:=3 on a world of 2: fleet_sim refuses to start (before, robot_2's navigation warned for ever
    that it had no pose); robots:=2 on the same world runs."""
    import rospkg
    world = os.path.join(rospkg.RosPack().get_path("fleet_launch"), "worlds", "corridors_%d.world" % world_robots)
    port = free_port()
    env = dict(ENV, ROS_MASTER_URI="http://127.0.0.1:%d" % port, ROS_HOME=str(tmp_path))
    args = ["roslaunch", "-p", str(port), "fleet_launch", "fleet.launch", "layout:=corridors", "robots:=%d" % robots,
            "world:=" + world, "output:=screen", "sharing:=false"]
    if refused:
        proc = subprocess.run(args, capture_output=True, text=True, env=env, timeout=120)
        out = proc.stdout + proc.stderr
        assert "fleet_sim cannot start: %s: holds 2 robot(s) (robot_0, robot_1), but 3 are to be driven " \
               "(robots:=3)" % world in out, out
        assert re.search(r"REQUIRED process \[fleet_sim-\d+\] has died", out), out
        return
    # Runs: the simulator comes up with both robots (the launch is stopped once it says so).
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env,
                            start_new_session=True)
    seen = []
    try:
        for line in proc.stdout:
            seen.append(line)
            if "fleet_sim: " in line and "2 robots (robot_0, robot_1)" in line:
                break
            if "has died" in line or "cannot start" in line:
                break
    finally:
        import signal
        os.killpg(proc.pid, signal.SIGINT)
        proc.wait(60)
    out = "".join(seen)
    assert "2 robots (robot_0, robot_1)" in out and "cannot start" not in out, out


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
