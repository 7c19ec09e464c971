"""What the replay checks before it replays: a map given on the command line must be the grid the bag
was recorded on (its /map: resolution, origin, size), and topics a bag legitimately lacks are not
warnings. Synthetic bags (synth.py, the corridor world: 40 x 12 m at 0.05 m, origin (0, 0))."""
import io
import os
import subprocess
import sys

import numpy as np
import pytest
import yaml
from PIL import Image

from sharing_replay import cli, synth
from sharing_replay.config import ORIGIN_TOLERANCE, MapData, map_differences

BLOCK_X = 20.0


def replay(bag, out, *args):
    stdout, stderr = io.StringIO(), io.StringIO()
    code, summary = cli.run([str(bag), "--out-dir", str(out), "--progress", "never", "--no-png"] + list(args),
                            stdout, stderr)
    return code, summary, stdout.getvalue(), stderr.getvalue()


SCRIPT = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scripts", "replay")


def replay_command(bag, out, *args):
    """The command line as a user runs it (its warnings go to stderr): (exit code, stdout, stderr)."""
    proc = subprocess.run([sys.executable, SCRIPT, str(bag), "--out-dir", str(out), "--progress", "never", "--no-png"]
                          + list(args), capture_output=True, text=True, timeout=300)
    return proc.returncode, proc.stdout, proc.stderr


@pytest.fixture(scope="module")
def world():
    return synth.corridor_world(block_x=BLOCK_X)


@pytest.fixture(scope="module")
def bag(world, tmp_path_factory):
    path = str(tmp_path_factory.mktemp("maps") / "one.bag")
    robot = synth.SynthRobot("robot_0", [(2.0, 6.0), (12.0, 6.0), (18.6, 6.0)], speed=1.0, stuck_at=[18.0])
    synth.write_bag(path, world, [robot], 30.0)
    return path


def write_map(folder, occupancy, resolution, origin, name="map"):
    """A map_server image + YAML of an OccupancyGrid-valued array (row 0 = lowest y)."""
    pixels = np.where(occupancy >= 100, 0, np.where(occupancy == 0, 254, 205)).astype(np.uint8)[::-1]
    image = folder / (name + ".pgm")
    Image.fromarray(pixels, mode="L").save(str(image))
    doc = folder / (name + ".yaml")
    doc.write_text(yaml.safe_dump({"image": image.name, "resolution": resolution, "origin": [origin[0], origin[1], 0.0],
                                   "negate": 0, "occupied_thresh": 0.65, "free_thresh": 0.196}))
    return str(doc), str(image)


def test_the_bags_own_map_given_again_replays_as_without_it(world, bag, tmp_path):
    doc, _image = write_map(tmp_path, world.occupancy, 0.05, (0.0, 0.0))
    code, summary, text, err = replay(bag, tmp_path / "given", "--map", doc)
    assert code == 0, text + err
    _code, own, _text, _err = replay(bag, tmp_path / "own")
    assert [o["ever_indexes"] for o in summary["obstacles"]] == [o["ever_indexes"] for o in own["obstacles"]]


def test_a_map_at_another_resolution_is_refused_naming_both(world, bag, tmp_path):
    # The case: an image replayed at a resolution it was not made at.
    _doc, image = write_map(tmp_path, world.occupancy, 0.05, (0.0, 0.0))
    code, summary, text, err = replay(bag, tmp_path / "out", "--map-image", image, "--resolution", "0.1")
    assert code == 2 and summary is None, text + err
    assert "is not the bag's /map" in err
    assert image in err and "0.1 m/cell" in err and "0.05 m/cell" in err          # both maps, named
    assert "resolution 0.1 m/cell, the bag's 0.05" in err
    assert "--allow-map-mismatch" in err


def test_a_map_of_another_size_is_refused(world, bag, tmp_path):
    doc, _image = write_map(tmp_path, world.occupancy[:, :-4], 0.05, (0.0, 0.0))
    code, _summary, _text, err = replay(bag, tmp_path / "out", "--map", doc)
    assert code == 2
    assert "size 796 x 240 cells, the bag's 800 x 240" in err


@pytest.mark.parametrize("offset, refused", [
    (0.0, False),
    (ORIGIN_TOLERANCE * 0.9, False),     # just inside: float noise of a YAML origin
    (ORIGIN_TOLERANCE * 1.1, True),      # just outside
    (0.05, True),                        # a whole cell
])
def test_origin_tolerance(world, bag, tmp_path, offset, refused):
    doc, _image = write_map(tmp_path, world.occupancy, 0.05, (offset, 0.0))
    code, _summary, text, err = replay(bag, tmp_path / "out", "--map", doc)
    if refused:
        assert code == 2 and "origin (%g, 0), the bag's (0, 0)" % offset in err, err
    else:
        assert code == 0, text + err


def test_resolution_tolerance():
    occupancy = np.zeros((10, 10), dtype=np.int8)
    bag_map = MapData(occupancy, 0.05, 0.0, 0.0, "bag")
    assert map_differences(MapData(occupancy, 0.05 * (1 + 0.9e-6), 0.0, 0.0, "given"), bag_map) == []
    assert map_differences(MapData(occupancy, 0.05 * (1 + 1.1e-6), 0.0, 0.0, "given"), bag_map) != []


def test_allow_map_mismatch_replays_on_the_given_map_and_says_so(world, bag, tmp_path):
    _doc, image = write_map(tmp_path, world.occupancy, 0.05, (0.0, 0.0))
    code, summary, text, err = replay(bag, tmp_path / "out", "--map-image", image, "--resolution", "0.1",
                                      "--allow-map-mismatch")
    assert summary is not None, text + err
    assert summary["problems"]["map_mismatch"] == 1
    assert "is not the bag's /map" in text and "replayed on the given map" in text
    assert summary["map"].endswith("map.pgm")
    code, _text, err = replay_command(bag, tmp_path / "cli", "--map-image", image, "--resolution", "0.1",
                                      "--allow-map-mismatch")
    assert "WARNING" in err and "is not the bag's /map" in err, err


def test_a_bag_without_map_takes_the_given_one_unchecked(world, tmp_path):
    path = str(tmp_path / "nomap.bag")
    robot = synth.SynthRobot("robot_0", [(2.0, 6.0), (18.6, 6.0)], speed=1.0, stuck_at=[18.0])
    synth.write_bag(path, world, [robot], 20.0, write_map=False)
    doc, _image = write_map(tmp_path, world.occupancy, 0.05, (0.0, 0.0))
    code, summary, text, err = replay(path, tmp_path / "out", "--map", doc)
    assert code == 0 and summary["obstacles_shared"] >= 1, text + err


def test_a_robot_without_trigger_or_plan_is_information_not_a_warning(world, tmp_path):
    """Two robots, robot_1 never stuck and never planning (a robot that was never sent anywhere): with
    --trigger auto nothing is missing; the summary says nothing can be proposed from robot_1."""
    path = str(tmp_path / "two.bag")
    robots = [synth.SynthRobot("robot_0", [(2.0, 6.0), (18.6, 6.0)], speed=1.0, stuck_at=[18.0]),
              synth.SynthRobot("robot_1", [(2.0, 2.0), (5.0, 2.0)], speed=0.5)]
    synth.write_bag(path, world, robots, 20.0)
    code, summary, text, err = replay(path, tmp_path / "out")
    assert code == 0, text + err
    assert summary["missing_topics"] == [] and summary["problems"] == {}
    assert summary["trigger_sources"] == {"robot_0": ["/robot_0/stuck_feedback"], "robot_1": []}
    code, text, err = replay_command(path, tmp_path / "cli")
    assert code == 0 and err == "", err
    assert "no trigger or plan in the bag for robot_1: nothing can be proposed from it" in text
    # Asked for by name, an absent trigger is still a warning and exit bit 32.
    code, summary, _text, _err = replay(path, tmp_path / "named", "--trigger", "stuck_feedback")
    assert code == 32 and summary["missing_topics"] == ["/robot_1/stuck_feedback"]
    code, _text, err = replay_command(path, tmp_path / "named_cli", "--trigger", "stuck_feedback")
    assert code == 32 and "missing topic /robot_1/stuck_feedback" in err, err


def test_a_single_robot_bag_with_its_footprint_replays(world, tmp_path):
    """A bag of one robot that recorded its footprint (record_bag.launch does): nobody to exclude, the
    footprint is not read, and the replay runs as without it."""
    import rosbag
    import rospy
    from geometry_msgs.msg import Point32, PolygonStamped
    path = str(tmp_path / "one_with_footprint.bag")
    robot = synth.SynthRobot("robot_0", [(2.0, 6.0), (18.6, 6.0)], speed=1.0, stuck_at=[18.0])
    synth.write_bag(path, world, [robot], 20.0)
    with rosbag.Bag(path, "a") as bag:
        msg = PolygonStamped()
        msg.header.frame_id = "map"
        msg.header.stamp = rospy.Time.from_sec(101.0)
        msg.polygon.points = [Point32(x, y, 0.0) for x, y in ((0, 0), (1, 0), (1, 1))]
        bag.write("/robot_0/move_base/global_costmap/footprint", msg, msg.header.stamp)
    code, summary, text, err = replay(path, tmp_path / "out")
    assert code == 0, text + err
    assert summary["obstacles_shared"] >= 1 and summary["robot_exclusion"]["robots"] == {}
