"""Headless PNG snapshots: walls, blocks, robots in their colours, laser rays."""

import numpy as np
from PIL import Image

import sim_test_helpers as h
from fleet_sim.sim import Simulation
from fleet_sim.snapshot import save_png
from fleet_sim.world import load_world


def _pixel(img, sim, x, y, ppm):
    g = sim.geom
    col = int((x - g.origin_x) * ppm)
    row = int((g.origin_y + g.size_y * g.resolution - y) * ppm)
    return tuple(img[row, col][:3])


def test_room_snapshot_shows_walls_block_robots_and_rays(tmp_path):
    sim = h.room_sim()
    sim.add_block("crate", 3.0, 0.0, 0.0, 0.4, 0.4)
    path = str(tmp_path / "room.png")
    size = save_png(sim, path, lasers=True, pixels_per_metre=20)
    img = np.asarray(Image.open(path).convert("RGB"))
    assert size == (img.shape[1], img.shape[0]) == (240, 200)     # 12 m x 10 m grid at 20 px/m
    assert _pixel(img, sim, -4.95, 0.0, 20) == (77, 77, 77)        # wall, gray30
    assert _pixel(img, sim, 3.0, 0.05, 20) == (255, 0, 0)           # the block
    assert _pixel(img, sim, -0.1, -0.1, 20) == (0, 0, 255)          # robot_0 blue
    assert _pixel(img, sim, -3.1, 2.1, 20) == (0, 255, 0)           # robot_1 green
    assert _pixel(img, sim, 1.5, 0.0, 20) != (255, 255, 255)        # a ray between robot and block
    assert (np.all(img == (255, 0, 255), axis=2)).sum() > 50        # laser endpoints

    save_png(sim, str(tmp_path / "plain.png"), lasers=False, pixels_per_metre=20)
    plain = np.asarray(Image.open(str(tmp_path / "plain.png")).convert("RGB"))
    assert _pixel(plain, sim, 1.5, 0.0, 20) == (255, 255, 255)
    assert not np.all(plain == (255, 0, 255), axis=2).any()


def test_willow_snapshot_is_bounded(tmp_path):
    sim = Simulation(load_world(h.WILLOW, log=lambda *a: None), raycast=h.raycaster())
    w, hgt = save_png(sim, str(tmp_path / "w.png"), lasers=True)
    assert w * hgt <= 4000 * 4000 and w > 1000
