"""move_base_fleet.launch (the real stack, issue 28): where stage_ros, move_base, navfn,
base_local_planner, map_server or fake_localization is missing it stops naming the package; with them
(here stand-in packages of those names, empty, on ROS_PACKAGE_PATH) it builds 1..10 robots with the
tutorials' files, per-robot frames, the sharing layer (or costmap_2d's ObstacleLayer with
sharing:=false) between the static and inflation layers, and refuses bad arguments by name."""
import os
import subprocess

import xml.etree.ElementTree as ET

import pytest
import yaml

ENV = dict(os.environ, ROS_IP="127.0.0.1", ROS_HOSTNAME="127.0.0.1")
LAUNCH = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "launch")
REAL_STACK = ("stage_ros", "move_base", "navfn", "base_local_planner", "map_server", "fake_localization")
PROGRAMS = {"stage_ros": ("stageros",), "move_base": ("move_base",), "map_server": ("map_server",),
            "fake_localization": ("fake_localization",)}


def roslaunch(env, *args):
    proc = subprocess.run(["roslaunch"] + list(args), capture_output=True, text=True, env=env, timeout=120)
    return proc.returncode, proc.stdout + proc.stderr


def installed(name):
    return subprocess.run(["rospack", "find", name], capture_output=True, env=ENV).returncode == 0


@pytest.fixture(scope="module")
def stand_ins(tmp_path_factory):
    """An environment where every real-stack package is found: the installed ones as they are, the
    others as stand-ins that hold only a package.xml and programs that exit 1 (roslaunch only needs to
    find them to build the launch; none is run)."""
    root = tmp_path_factory.mktemp("stand_ins")
    for name in REAL_STACK:
        if installed(name):
            continue
        (root / name).mkdir()
        (root / name / "package.xml").write_text(
            '<?xml version="1.0"?>\n<package format="2"><name>%s</name><version>0.0.0</version>'
            '<description>stand-in</description><maintainer email="x@example.org">x</maintainer>'
            '<license>BSD</license><buildtool_depend>catkin</buildtool_depend></package>\n' % name)
        for program in PROGRAMS.get(name, ()):
            (root / name / program).write_text("#!/bin/sh\nexit 1\n")
            (root / name / program).chmod(0o755)
    return dict(ENV, ROS_PACKAGE_PATH=str(root) + os.pathsep + ENV.get("ROS_PACKAGE_PATH", ""))


def fleet_launch_default(name):
    """The default of an argument of fleet.launch (the stand-in fleet): both launches share them."""
    root = ET.parse(os.path.join(LAUNCH, "launch", "fleet.launch")).getroot()
    return yaml.safe_load([a.get("default") for a in root.iter("arg") if a.get("name") == name][0])


def params(env, *args):
    """The launch's parameters: roslaunch --dump-params prints them as one YAML mapping."""
    proc = subprocess.run(["roslaunch", "--dump-params", "fleet_launch", "move_base_fleet.launch"] + list(args),
                          capture_output=True, text=True, env=env, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return yaml.safe_load(proc.stdout)


def without_upstream(env):
    """The environment with the upstream workspace make setup built taken off ROS_PACKAGE_PATH: the real stack's
    packages are then missing, as on a machine without them."""
    cache = os.path.realpath(env.get("FLEET_UPSTREAM_CACHE", os.path.expanduser("~/.cache/fleet_upstream")))
    kept = [p for p in env.get("ROS_PACKAGE_PATH", "").split(os.pathsep)
            if p and not os.path.realpath(p).startswith(cache + os.sep)]
    return dict(env, ROS_PACKAGE_PATH=os.pathsep.join(kept))


def test_a_missing_package_stops_the_launch_naming_it():
    env = without_upstream(ENV)
    absent = [name for name in REAL_STACK
              if subprocess.run(["rospack", "find", name], capture_output=True, env=env).returncode != 0]
    assert absent, "the real stack is installed outside make setup's workspace: nothing to take away"
    rc, out = roslaunch(env, "--nodes", "fleet_launch", "move_base_fleet.launch")
    assert rc != 0, out
    assert any("not found" in out and ": %s\n" % name in out for name in absent), out


@pytest.mark.parametrize("robots", [1, 2, 10])
def test_each_robot_gets_move_base_fake_localization_handler_and_bridge(stand_ins, robots):
    rc, out = roslaunch(stand_ins, "--nodes", "fleet_launch", "move_base_fleet.launch", "robots:=%d" % robots)
    assert rc == 0, out
    listed = set(out.split())
    for i in range(robots):
        for node in ("move_base", "fake_localization", "sharing_handler", "coaty_bridge"):
            assert "/robot_%d/%s" % (i, node) in listed, out
    assert "/robot_%d/move_base" % robots not in listed
    assert {"/stageros", "/map_server", "/fleet_broker"} <= listed


def test_the_tutorials_files_with_the_sharing_layer_and_per_robot_frames(stand_ins):
    p = params(stand_ins, "robots:=2")
    with open(os.path.join(LAUNCH, "config", "move_base", "costmap_common_params.yaml")) as f:
        common = yaml.safe_load(f)
    for i in range(2):
        mb = "/robot_%d/move_base/" % i
        assert [(l["name"], l["type"]) for l in p[mb + "global_costmap/plugins"]] == [
            ("static_layer", "costmap_2d::StaticLayer"), ("sharing_layer", "sharing_layer::SharingLayer"),
            ("inflation_layer", "costmap_2d::InflationLayer")]
        assert p[mb + "global_costmap/robot_base_frame"] == "robot_%d/base_link" % i
        assert p[mb + "local_costmap/global_frame"] == "robot_%d/odom" % i
        assert p[mb + "local_costmap/robot_base_frame"] == "robot_%d/base_link" % i
        assert p[mb + "global_costmap/global_frame"] == "map"
        # the tutorials' files as they are: in each costmap, and in the marking layer's namespace
        for ns in ("global_costmap/", "local_costmap/", "global_costmap/sharing_layer/"):
            for key in ("observation_sources", "obstacle_range", "raytrace_range", "footprint"):
                assert p[mb + ns + key] == common[key], ns + key
        assert p[mb + "TrajectoryPlannerROS/max_vel_x"] == 0.65
        assert p[mb + "controller_frequency"] == 10.0
        assert p["/robot_%d/fake_localization/odom_frame_id" % i] == "robot_%d/odom" % i
        assert p["/robot_%d/fake_localization/base_frame_id" % i] == "robot_%d/base_link" % i
        assert p["/robot_%d/sharing_handler/obstacle_duration" % i] == fleet_launch_default("obstacle_duration")
        assert p["/robot_%d/coaty_bridge/footprint_topic" % i] == "move_base/global_costmap/footprint"
    assert p["/use_sim_time"] is True
    assert p["/fleet/goals"].endswith("/worlds/corridors_goals.yaml")


def test_sharing_off_is_the_plain_obstacle_layer_and_no_fleet_nodes(stand_ins):
    p = params(stand_ins, "sharing:=false")
    assert [l["type"] for l in p["/robot_0/move_base/global_costmap/plugins"]] == [
        "costmap_2d::StaticLayer", "costmap_2d::ObstacleLayer", "costmap_2d::InflationLayer"]
    assert p["/robot_0/move_base/global_costmap/obstacle_layer/observation_sources"] == "base_scan"
    rc, out = roslaunch(stand_ins, "--nodes", "fleet_launch", "move_base_fleet.launch", "sharing:=false")
    assert rc == 0, out
    assert not {"/fleet_broker", "/robot_0/sharing_handler", "/robot_0/coaty_bridge"} & set(out.split()), out


@pytest.mark.parametrize("layout", ["corridors", "facility", "deadend"])
def test_the_layout_picks_world_and_map(stand_ins, layout):
    rc, out = roslaunch(stand_ins, "--args", "/stageros", "fleet_launch", "move_base_fleet.launch",
                        "layout:=%s" % layout, "robots:=3")
    assert rc == 0, out
    assert "/with_xvfb " in out and " -u " in out and "/worlds/%s_3.world " % layout in out, out
    rc, out = roslaunch(stand_ins, "--args", "/map_server", "fleet_launch", "move_base_fleet.launch", "layout:=%s" % layout)
    assert rc == 0, out
    assert "/worlds/%s.yaml " % layout in out, out


def test_stage_display_none_runs_stageros_without_a_window(stand_ins):
    rc, out = roslaunch(stand_ins, "--args", "/stageros", "fleet_launch", "move_base_fleet.launch", "stage_display:=none")
    assert rc == 0, out
    assert "with_xvfb" not in out and " -g -u " in " " + out, out


@pytest.mark.parametrize("arg, message", [
    ("robots:=0", "robots:=0: robots must be a whole number from 1 to 10"),
    ("robots:=11", "robots:=11: robots must be a whole number from 1 to 10"),
    ("obstacle_duration:=0", "obstacle_duration:=0: obstacle_duration must be a number of seconds, at least 1"),
    ("obstacle_duration:=long", "obstacle_duration:=long: obstacle_duration must be a number of seconds, at least 1"),
    ("layout:=nowhere", "layout:=nowhere: layout must be corridors, facility or deadend"),
    ("stage_display:=window", "stage_display:=window: stage_display must be xvfb, screen or none"),
    ("speedup:=0", "speedup:=0: speedup must be a number above 0"),
    ("speedup:=-1", "speedup:=-1: speedup must be a number above 0"),
    ("speedup:=fast", "speedup:=fast: speedup must be a number above 0"),
])
def test_bad_argument_is_refused_naming_it_its_value_and_what_it_must_be(stand_ins, arg, message):
    rc, out = roslaunch(stand_ins, "--nodes", "fleet_launch", "move_base_fleet.launch", arg)
    assert rc != 0, out
    assert "Invalid <arg> tag: " + message in out, out
    assert "is not defined" not in out and "could not convert" not in out, out


def test_speedup_reaches_stage_through_stage_world(stand_ins):
    rc, out = roslaunch(stand_ins, "--args", "/stageros", "fleet_launch", "move_base_fleet.launch", "speedup:=2.5")
    assert rc == 0, out
    assert "/stage_world --speedup 2.5 -u " in out, out
    rc, out = roslaunch(stand_ins, "--args", "/stageros", "fleet_launch", "move_base_fleet.launch")
    assert "/stage_world --speedup 1 -u " in out, out


def test_record_true_records_what_the_replay_needs(stand_ins):
    """record:=true as in fleet.launch: fleet_sim's record_bag.launch, whose topics include each robot's
    footprint (the replay places the other robots with it)."""
    rc, out = roslaunch(stand_ins, "--nodes", "fleet_launch", "move_base_fleet.launch", "record:=true")
    assert rc == 0 and "/record_bag" in out.split(), out
    rc, out = roslaunch(stand_ins, "--args", "/record_bag", "fleet_launch", "move_base_fleet.launch", "record:=true",
                        "bag:=/tmp/x.bag")
    assert rc == 0 and "-O /tmp/x.bag" in out and "global_costmap/footprint" in out, out
    rc, out = roslaunch(stand_ins, "--nodes", "fleet_launch", "move_base_fleet.launch")
    assert rc == 0 and "/record_bag" not in out.split(), out
