"""Property: for any floorplan pose, the map map_server serves of its bitmap and the grid
the simulator rasterises agree pixel by pixel through frames.world_from_map."""
import math
import os
import tempfile

import numpy as np
from hypothesis import given, settings, strategies as st
from PIL import Image

import sim_test_helpers  # noqa: F401  (puts fleet_sim on the path)
from fleet_sim import frames
from fleet_sim.map_io import load_map_image
from fleet_sim.world import load_world
from fleet_sim.world.raster import GridGeometry, paint_floorplan

RNG = np.random.default_rng(5)
PIXELS = np.where(RNG.random((10, 16)) < 0.3, 0, 254).astype(np.uint8)   # 1.6 m x 1.0 m at 0.1 m/px


@settings(max_examples=30, deadline=None)
@given(x=st.floats(-50, 50), y=st.floats(-50, 50), yaw_deg=st.floats(-180, 180),
       origin_x=st.floats(-5, 5), origin_y=st.floats(-5, 5), origin_yaw=st.floats(-3.0, 3.0))
def test_map_and_simulated_walls_agree_for_any_floorplan_pose(x, y, yaw_deg, origin_x, origin_y, origin_yaw):
    with tempfile.TemporaryDirectory() as tmp:
        Image.fromarray(PIXELS).save(os.path.join(tmp, "plan.png"))
        with open(os.path.join(tmp, "w.world"), "w") as handle:
            handle.write('resolution 0.02\nmodel( bitmap "plan.png" size [1.6 1.0 0.5] '
                         'pose [%r %r 0 %r] )\n' % (x, y, yaw_deg))
        world = load_world(os.path.join(tmp, "w.world"), log=lambda *a: None)
        m = load_map_image(os.path.join(tmp, "plan.png"), 0.1, origin=(origin_x, origin_y, origin_yaw),
                           occupied_thresh=0.5)
    fp = world.floorplans[0]
    geom = GridGeometry.covering(world.bounds(1.0), world.resolution)
    grid = np.zeros((geom.size_y, geom.size_x), dtype=np.uint8)
    paint_floorplan(grid, geom, fp)

    t_world_map = frames.world_from_map(fp.pose, fp.size, m.origin)
    rows, cols = np.mgrid[0:m.height, 0:m.width]
    # pixel centres in the map frame (map_server: origin is the lower-left corner, rotated by its yaw)
    px = (cols + 0.5) * m.resolution
    py = (rows + 0.5) * m.resolution
    mx, my = frames.apply(m.origin, px, py)
    wx, wy = frames.apply(t_world_map, mx, my)
    gc = np.floor((wx - geom.origin_x) / geom.resolution).astype(int)
    gr = np.floor((wy - geom.origin_y) / geom.resolution).astype(int)
    np.testing.assert_array_equal(grid[gr, gc] != 0, m.data == 100)
    # Compared as a difference: pi and -pi are the same heading (yaw 180 deg normalised either way).
    assert abs(frames.normalize_angle(t_world_map[2] + m.origin[2] - math.radians(yaw_deg))) < 1e-9
