"""fleet_tests.run_picture: the picture of a scenario run puts the shared cells, the trails and the
walls where they are in the world, and refuses a map it cannot draw."""
import os

import pytest
from nav_msgs.msg import OccupancyGrid
from PIL import Image

from fleet_tests.run_picture import SHARED, TRAIL_COLOURS, draw_run
from sharing_msgs.msg import SharedObstacle


def grid(width=40, height=30, resolution=0.1):
    g = OccupancyGrid()
    g.info.width, g.info.height, g.info.resolution = width, height, resolution
    g.info.origin.position.x, g.info.origin.position.y = -1.0, 2.0
    g.data = [0] * (width * height)
    for ix in range(width):                      # a wall along the bottom row
        g.data[ix] = 100
    return g


def pixel(image, g, x, y, header=36):
    scale = max(1, int(round(40 * g.info.resolution)))
    px = int((x - g.info.origin.position.x) / g.info.resolution * scale)
    py = int(header + g.info.height * scale - (y - g.info.origin.position.y) / g.info.resolution * scale)
    return image.getpixel((px, py))


def test_cells_trails_and_walls_are_drawn_where_they_are(tmp_path):
    g = grid()
    shared = SharedObstacle(size_x=40, size_y=30, resolution=0.1, origin_x=-1.0, origin_y=2.0,
                            marked_indexes=[15 * 40 + 30])   # cell (30, 15): world (2.05, 3.55)
    facility = {"blocks": {"block": {"pose": [2.05, 3.55, 0.0], "size": [0.6, 0.2]}}}
    trails = {"robot_0": [(0.0, -0.5, 3.0), (1.0, 0.5, 3.0)], "robot_1": [(0.0, 0.0, 4.5), (1.0, 1.0, 4.5)]}
    path = draw_run(str(tmp_path / "run.png"), g, facility, trails, [shared], "test run")
    image = Image.open(path).convert("RGB")
    assert pixel(image, g, 2.05, 3.55) == SHARED
    assert pixel(image, g, 0.0, 3.0) == TRAIL_COLOURS[0]
    assert pixel(image, g, 0.5, 4.5) == TRAIL_COLOURS[1]
    assert pixel(image, g, 0.0, 2.05) == (60, 60, 60)        # the wall row
    assert pixel(image, g, 0.0, 4.0) == (255, 255, 255)      # free space


def test_a_map_it_cannot_draw_is_refused(tmp_path):
    bad = grid()
    bad.data = bad.data[:-1]
    with pytest.raises(ValueError, match="cannot draw the run"):
        draw_run(str(tmp_path / "bad.png"), bad, {}, {}, [], "bad")
    assert not os.path.exists(tmp_path / "bad.png")
