"""Worlds read the same way as Stage reads them (issue 49): a ranger's beams hit only robots whose body spans
their height, and a position model without a ranger is a movable block, not a robot."""
import math
import os
import shutil

import pytest

import sim_test_helpers as h
from fleet_sim.sim import BEAM_ABOVE_SENSOR_POSE, Simulation, beam_hits_body
from fleet_sim.world import load_world

FRONT = 90


def world(tmp_path, laser_z, body_height=0.25, extra=""):
    """room.world's room with two robots face to face 3 m apart, the laser at pose z laser_z."""
    shutil.copy(os.path.join(h.DATA, "room.pgm"), str(tmp_path / "room.pgm"))
    text = """
define floorplan model ( color "gray30" ranger_return 1 )
define testlaser ranger ( sensor( range [ 0.0 30.0 ] fov 180 samples 181 ) size [ 0.05 0.05 0.1 ] )
define testbot position ( size [ 0.4 0.4 %g ] drive "omni" testlaser( pose [ 0.1 0 %g 0 ] ) )
resolution 0.02
interval_sim 100
floorplan ( name "room" bitmap "room.pgm" size [10.0 8.0 0.5] pose [0 0 0 0] )
testbot( pose [ 0 0 0 0 ] name "bot0" )
testbot( pose [ 3 0 0 180 ] name "bot1" )
%s
""" % (body_height, laser_z, extra)
    path = tmp_path / "heights.world"
    path.write_text(text)
    return Simulation(load_world(str(path), log=lambda *a: None), raycast=h.raycaster())


def test_a_beam_just_below_the_top_of_the_other_body_hits_it_and_just_above_passes_over(tmp_path):
    # the beam runs at body 0.25 + laser z + 0.01: at z -0.015 it is 0.245 m up (hits), at -0.005 0.255 (over)
    below = world(tmp_path, -0.015)
    assert below.robots[0].scans[0][FRONT] == pytest.approx(2.7, abs=0.03)   # the other robot's face at 2.8 - 0.1
    over = world(tmp_path, -0.005)
    assert over.robots[0].scans[0][FRONT] == pytest.approx(4.8, abs=0.03)    # the room's wall at 4.9 - 0.1


def test_beam_height_rule_at_its_limits():
    assert beam_hits_body(0.25, -0.01 - BEAM_ABOVE_SENSOR_POSE, 0.24 + 1e-9)
    assert not beam_hits_body(0.25, -0.01 - BEAM_ABOVE_SENSOR_POSE, 0.24 - 1e-3)
    assert not beam_hits_body(0.25, -0.3, 0.25)            # under the floor
    assert beam_hits_body(0.0, 0.0, 0.25) and beam_hits_body(0.25, 0.0, 0.0)  # no heights (Stage 3): every beam


def test_a_position_model_without_a_ranger_is_a_movable_block_not_a_robot(tmp_path):
    sim = world(tmp_path, -0.1, extra="""
define box position ( size [0.5 0.5 0.5] drive "omni" obstacle_return 0 )
box( pose [ 1.5 -2 0 0 ] size [ 2.0 0.3 0.5 ] name "block_a" )
""")
    assert [r.spec.name for r in sim.robots] == ["bot0", "bot1"]
    block = sim.blocks["block_a"]
    assert block.size == (2.0, 0.3) and not block.obstacle and block.visible
    # bot0 turned to face -y sees the block's face 1.85 m ahead of its laser
    sim.teleport(0, (1.5, 0.0, -math.pi / 2))
    assert sim.robots[0].scans[0][FRONT] == pytest.approx(1.75, abs=0.03)
    sim.move_block("block_a", 1.5, -3.0, 0.0)
    assert sim.robots[0].scans[0][FRONT] == pytest.approx(2.75, abs=0.03)


def test_the_facility_worlds_robots_see_each_other_as_in_stage():
    worlds = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
                          "launch", "worlds")
    sim = Simulation(load_world(os.path.join(worlds, "facility_2.world"), log=lambda *a: None),
                     raycast=h.raycaster())
    assert [r.spec.name for r in sim.robots] == ["robot_0", "robot_1"]
    assert set(sim.blocks) == {"block_middle", "block_right"}
    # robot_1 (15.0, 1.0) seen from robot_0 (13.6, 1.0, facing +y): the beam to the right, -90 deg, of 1081 over
    # 270.25 deg, runs along +x from the laser at (13.6, 1.275) to robot_1's near face at x = 15.0 - 0.325
    ranger = sim.robots[0].spec.rangers[0]
    angles = list(ranger.beam_angles())
    right = min(range(len(angles)), key=lambda k: abs(angles[k] + math.pi / 2))
    assert sim.robots[0].scans[0][right] == pytest.approx(1.4 - 0.325, abs=0.03)
