"""Helpers for fleet_sim's pytest files (unique module name: pytest imports every
package's test folder in one run)."""
import math
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(HERE), "src"))

DATA = os.path.join(HERE, "data")
SHARED = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(HERE))), "shared", "data")
if not os.path.isdir(SHARED):
    SHARED = "/work/shared/data"
WILLOW = os.path.join(SHARED, "stage_worlds", "willow", "willow-pr2-multi.world")
SIMPLE = os.path.join(SHARED, "stage_worlds", "stage_examples", "simple.world")
WILLOW_PGM = os.path.join(SHARED, "stage_worlds", "maps", "willow-full.pgm")


def reference_raycast(grid, resolution, origin_x, origin_y, sensor_x, sensor_y, angles,
                      min_range, max_range):
    """NumPy stand-in with the contract of sharing_layer_cpp.core.raycast_ranges
    (Amanatides–Woo grid traversal; distance to the boundary of the first cell
    != 0; max_range when nothing is hit or the ray leaves the grid)."""
    angles = np.asarray(angles, dtype=np.float64)
    n = angles.size
    h, w = grid.shape
    gx = (sensor_x - origin_x) / resolution
    gy = (sensor_y - origin_y) / resolution
    dx, dy = np.cos(angles), np.sin(angles)
    cx = np.full(n, int(math.floor(gx)))
    cy = np.full(n, int(math.floor(gy)))
    step_x = np.where(dx > 0, 1, -1)
    step_y = np.where(dy > 0, 1, -1)
    with np.errstate(divide="ignore", invalid="ignore"):
        tdx = np.where(dx != 0, np.abs(1.0 / dx), np.inf)
        tdy = np.where(dy != 0, np.abs(1.0 / dy), np.inf)
        tmx = np.where(dx > 0, (cx + 1 - gx) * tdx, np.where(dx < 0, (gx - cx) * tdx, np.inf))
        tmy = np.where(dy > 0, (cy + 1 - gy) * tdy, np.where(dy < 0, (gy - cy) * tdy, np.inf))
    out = np.full(n, max_range, dtype=np.float64)
    t = np.zeros(n)
    active = np.ones(n, dtype=bool)
    limit = max_range / resolution
    inside0 = (cx >= 0) & (cx < w) & (cy >= 0) & (cy < h)
    if inside0[0] and grid[cy[0], cx[0]] != 0:
        return np.full(n, max(min_range, 0.0), dtype=np.float32)
    active &= inside0
    while active.any():
        use_x = tmx < tmy
        t = np.where(use_x, tmx, tmy)
        cx = np.where(active & use_x, cx + step_x, cx)
        cy = np.where(active & ~use_x, cy + step_y, cy)
        tmx = np.where(active & use_x, tmx + tdx, tmx)
        tmy = np.where(active & ~use_x, tmy + tdy, tmy)
        too_far = t > limit
        inside = (cx >= 0) & (cx < w) & (cy >= 0) & (cy < h)
        active &= ~too_far & inside
        hit = np.zeros(n, dtype=bool)
        idx = np.nonzero(active)[0]
        hit[idx] = grid[cy[idx], cx[idx]] != 0
        out[hit] = t[hit] * resolution
        active &= ~hit
    out = np.minimum(out, max_range)
    out = np.maximum(out, min_range)
    return out.astype(np.float32)


def raycaster():
    """The C++ core when it is built, else the NumPy reference."""
    try:
        from sharing_layer_cpp import core
        return core.raycast_ranges
    except ImportError:
        return reference_raycast
