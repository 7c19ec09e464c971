"""The simulator node refuses a bad parameter at start-up with an error naming it (a real fleet_sim
process under roslaunch with its own master; test_sim_messages checks the same rule without one)."""
import os
import re
import socket
import subprocess

import sim_test_helpers as h


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def launch_sim(tmp_path, world, extra_params=""):
    """roslaunch of fleet_sim alone (required) on ``world`` with ``extra_params`` (param elements) on a master of its
    own: its whole output."""
    launch = tmp_path / "sim.launch"
    launch.write_text("""<launch>
  <param name="/use_sim_time" value="true"/>
  <node pkg="fleet_sim" type="fleet_sim" name="fleet_sim" required="true" output="screen">
    <param name="world" value="%s"/>
    %s
  </node>
</launch>
""" % (world, extra_params))
    port = free_port()
    env = dict(os.environ, ROS_IP="127.0.0.1", ROS_HOSTNAME="127.0.0.1",
               ROS_MASTER_URI="http://127.0.0.1:%d" % port, ROS_HOME=str(tmp_path))
    proc = subprocess.run(["roslaunch", "-p", str(port), str(launch)], capture_output=True, text=True,
                          env=env, timeout=120)
    return proc.stdout + proc.stderr


def test_a_negative_transform_tolerance_stops_the_node_naming_the_parameter(tmp_path):
    out = launch_sim(tmp_path, os.path.join(h.DATA, "room.world"),
                     '<param name="transform_tolerance" value="-0.5"/>')
    assert re.search(r"fleet_sim cannot start: parameter ~transform_tolerance must be >= 0, got -0\.5", out), out
    assert re.search(r"REQUIRED process \[fleet_sim-\d+\] has died", out), out


def test_a_world_whose_floorplan_bitmap_is_missing_stops_the_node_naming_it(tmp_path):
    """rosrun fleet_sim fleet_sim _world:=... (no ~strict): before, it logged one ERROR and simulated a
    world without walls."""
    world = os.path.join(h.DATA, "broken", "missing_bitmap.world")
    out = launch_sim(tmp_path, world)
    assert "fleet_sim cannot start: %s:3: bitmap %s not found: without it the world has no walls" % (
        world, os.path.join(h.DATA, "broken", "does_not_exist.png")) in out, out
    assert re.search(r"REQUIRED process \[fleet_sim-\d+\] has died", out), out
