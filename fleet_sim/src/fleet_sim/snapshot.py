"""Headless PNG pictures of a simulation: walls, blocks, robots in their colours, laser rays."""
import math

import numpy as np

from fleet_sim import frames
from fleet_sim.world.model import rect_corners

FREE = (255, 255, 255)
MAX_PIXELS = 4000 * 4000


def render(sim, lasers=True, pixels_per_metre=None):
    """A PIL image of the world (north up: +y of the world frame is up).

    ``pixels_per_metre`` defaults to one pixel per grid cell, capped so the
    picture stays under 16 Mpixel.
    """
    from PIL import Image, ImageDraw
    g = sim.geom
    ppm = pixels_per_metre or 1.0 / g.resolution
    width_m, height_m = g.size_x * g.resolution, g.size_y * g.resolution
    if width_m * height_m * ppm * ppm > MAX_PIXELS:
        ppm = math.sqrt(MAX_PIXELS / (width_m * height_m))
    w = max(1, int(round(width_m * ppm)))
    h = max(1, int(round(height_m * ppm)))

    rgb = np.empty((g.size_y, g.size_x, 3), dtype=np.uint8)
    rgb[:] = FREE
    wall_color = sim.world.floorplans[0].color if sim.world.floorplans else (77, 77, 77)
    rgb[sim._base_laser != 0] = wall_color
    img = Image.fromarray(rgb[::-1]).resize((w, h), Image.NEAREST)
    draw = ImageDraw.Draw(img)

    def px(x, y):
        return ((x - g.origin_x) * ppm, (g.origin_y + height_m - y) * ppm)

    for b in sim.blocks.values():
        draw.polygon([px(*c) for c in rect_corners(b.pose, b.size)], fill=tuple(b.color))
    if lasers:
        for r in sim.robots:
            for k, ranger in enumerate(r.spec.rangers):
                if k >= len(r.scans):
                    continue
                sx, sy, sth = frames.compose(r.pose, ranger.pose)
                ang = sth + ranger.beam_angles()
                rng = r.scans[k].astype(np.float64)
                ex, ey = sx + rng * np.cos(ang), sy + rng * np.sin(ang)
                ray = tuple(int(0.5 * c + 127) for c in r.spec.color)
                step = max(1, len(rng) // 360)
                for i in range(0, len(rng), step):
                    draw.line([px(sx, sy), px(ex[i], ey[i])], fill=ray)
                for i in range(len(rng)):
                    if rng[i] < ranger.range_max:
                        x, y = px(ex[i], ey[i])
                        draw.point((x, y), fill=(255, 0, 255))
    for r in sim.robots:
        corners = rect_corners(r.pose, r.spec.size, r.spec.origin)
        draw.polygon([px(*c) for c in corners], fill=tuple(r.spec.color), outline=(0, 0, 0))
        nose = frames.apply(r.pose, 0.5 * r.spec.size[0] + r.spec.origin[0], 0.0)
        draw.line([px(r.pose[0], r.pose[1]), px(*nose)], fill=(0, 0, 0), width=max(1, int(ppm * 0.05)))
    return img


def save_png(sim, path, lasers=True, pixels_per_metre=None):
    """Writes the picture to ``path``; returns (width, height)."""
    img = render(sim, lasers=lasers, pixels_per_metre=pixels_per_metre)
    img.save(path, format="PNG")
    return img.size
