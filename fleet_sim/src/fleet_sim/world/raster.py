"""Rasterising a world into occupancy grids (row 0 = lowest y, column 0 = lowest x).

A cell belongs to a shape when its centre lies inside it; a shape smaller than a
cell still gets the cell under its centre, so nothing thin vanishes.
"""
import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class GridGeometry:
    """size_x × size_y cells of ``resolution`` metres, lower-left corner at origin."""
    resolution: float
    origin_x: float
    origin_y: float
    size_x: int
    size_y: int

    @classmethod
    def covering(cls, bounds, resolution):
        min_x, min_y, max_x, max_y = bounds
        size_x = max(1, int(math.ceil((max_x - min_x) / resolution - 1e-9)))
        size_y = max(1, int(math.ceil((max_y - min_y) / resolution - 1e-9)))
        return cls(resolution, min_x, min_y, size_x, size_y)

    def cell_of(self, x, y):
        """(col, row) of a world point; may be outside the grid."""
        return (int(math.floor((x - self.origin_x) / self.resolution)),
                int(math.floor((y - self.origin_y) / self.resolution)))

    def contains(self, x, y):
        c, r = self.cell_of(x, y)
        return 0 <= c < self.size_x and 0 <= r < self.size_y

    def bbox_cells(self, corners):
        """Clipped (c0, r0, c1, r1) half-open cell box around points, or None if outside."""
        xs = [p[0] for p in corners]
        ys = [p[1] for p in corners]
        c0, r0 = self.cell_of(min(xs), min(ys))
        c1, r1 = self.cell_of(max(xs), max(ys))
        c0, r0 = max(c0, 0), max(r0, 0)
        c1, r1 = min(c1 + 1, self.size_x), min(r1 + 1, self.size_y)
        if c0 >= c1 or r0 >= r1:
            return None
        return c0, r0, c1, r1


def _local_coords(geom, box, pose):
    """Cell-centre coordinates of a cell box, in the frame of ``pose``."""
    c0, r0, c1, r1 = box
    xs = geom.origin_x + (np.arange(c0, c1) + 0.5) * geom.resolution
    ys = geom.origin_y + (np.arange(r0, r1) + 0.5) * geom.resolution
    dx = xs[None, :] - pose[0]
    dy = ys[:, None] - pose[1]
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return c * dx + s * dy, -s * dx + c * dy


def rect_cells(geom, pose, size, origin=(0.0, 0.0)):
    """(rows, cols) index arrays of the cells of a rotated rectangle.

    ``origin`` shifts the rectangle's centre in its own frame (Stage's ``origin``).
    """
    hx, hy = size[0] / 2.0, size[1] / 2.0
    c, s = math.cos(pose[2]), math.sin(pose[2])
    corners = []
    for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
        lx, ly = origin[0] + sx * hx, origin[1] + sy * hy
        corners.append((pose[0] + c * lx - s * ly, pose[1] + s * lx + c * ly))
    box = geom.bbox_cells(corners)
    if box is None:
        return np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp)
    lx, ly = _local_coords(geom, box, pose)
    inside = (np.abs(lx - origin[0]) <= hx) & (np.abs(ly - origin[1]) <= hy)
    rows, cols = np.nonzero(inside)
    rows = rows + box[1]
    cols = cols + box[0]
    if rows.size == 0:
        cx = pose[0] + c * origin[0] - s * origin[1]
        cy = pose[1] + s * origin[0] + c * origin[1]
        col, row = geom.cell_of(cx, cy)
        if 0 <= col < geom.size_x and 0 <= row < geom.size_y:
            return np.array([row], dtype=np.intp), np.array([col], dtype=np.intp)
    return rows, cols


def paint_floorplan(grid, geom, floorplan, value=1, rows_per_chunk=256):
    """Paints a floorplan's dark pixels (and its boundary) into ``grid``.

    The bitmap is stretched to the model's size and centred on its pose; each
    cell takes the pixel under its centre (nearest neighbour).
    """
    img = floorplan.occupied
    h, w = img.shape
    sx, sy = floorplan.size
    hx, hy = sx / 2.0, sy / 2.0
    c, s = math.cos(floorplan.pose[2]), math.sin(floorplan.pose[2])
    corners = [(floorplan.pose[0] + c * a - s * b, floorplan.pose[1] + s * a + c * b)
               for a, b in ((-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy))]
    box = geom.bbox_cells(corners)
    if box is None:
        return
    c0, r0, c1, r1 = box
    edge = geom.resolution
    for rr in range(r0, r1, rows_per_chunk):
        sub = (c0, rr, c1, min(rr + rows_per_chunk, r1))
        lx, ly = _local_coords(geom, sub, floorplan.pose)
        inside = (np.abs(lx) < hx) & (np.abs(ly) < hy)
        col = np.floor((lx + hx) / sx * w).astype(np.intp)
        row = np.floor((hy - ly) / sy * h).astype(np.intp)
        np.clip(col, 0, w - 1, out=col)
        np.clip(row, 0, h - 1, out=row)
        solid = inside & img[row, col]
        if floorplan.boundary:
            solid |= inside & ((hx - np.abs(lx) < edge) | (hy - np.abs(ly) < edge))
        view = grid[sub[1]:sub[3], c0:c1]
        view[solid] = value
