"""PNG picture of one robot's view, like the thesis's Figures 5.x: the inflated costmap in grey,
shared obstacles in their own colour, the robot's footprint and the plan."""
import math

import numpy as np
from PIL import Image, ImageDraw

SHARED_RGB = (220, 30, 160)     # magenta: shared obstacles
LETHAL_RGB = (20, 20, 20)
PLAN_RGB = (0, 170, 0)
ROBOT_RGB = (30, 90, 230)


def render(costs, shared_mask, geometry, pose=None, footprint=(), plan_xy=None, scale=2):
    """Returns a PIL image; costs (size_y, size_x) uint8, shared_mask bool of the same shape."""
    c = costs.astype(np.float32)
    grey = np.where(costs == 255, 200.0, 255.0 - c * (200.0 / 253.0)).astype(np.uint8)
    rgb = np.stack([grey, grey, grey], axis=-1)
    rgb[costs == 254] = LETHAL_RGB
    rgb[shared_mask] = SHARED_RGB
    img = Image.fromarray(np.ascontiguousarray(rgb[::-1]), "RGB")   # row 0 of the image is the top
    if scale != 1:
        img = img.resize((img.width * scale, img.height * scale), Image.NEAREST)
    draw = ImageDraw.Draw(img)
    height = geometry.size_y

    def px(x, y):
        return ((x - geometry.origin_x) / geometry.resolution * scale,
                (height - (y - geometry.origin_y) / geometry.resolution) * scale)

    if plan_xy is not None and len(plan_xy) > 1:
        draw.line([px(x, y) for x, y in plan_xy], fill=PLAN_RGB, width=max(1, scale))
    if pose is not None and footprint:
        cy, sy = math.cos(pose[2]), math.sin(pose[2])
        poly = [px(pose[0] + cy * fx - sy * fy, pose[1] + sy * fx + cy * fy) for fx, fy in footprint]
        draw.polygon(poly, outline=ROBOT_RGB)
        draw.line([px(pose[0], pose[1]), px(pose[0] + 0.5 * cy, pose[1] + 0.5 * sy)], fill=ROBOT_RGB,
                  width=max(1, scale))
    return img


def crop_around(img, geometry, centre, half_size_m, scale=2):
    """The part of a rendered image within half_size_m of centre (for the report's close-ups)."""
    cx = (centre[0] - geometry.origin_x) / geometry.resolution * scale
    cy = (geometry.size_y - (centre[1] - geometry.origin_y) / geometry.resolution) * scale
    r = half_size_m / geometry.resolution * scale
    return img.crop((int(max(0, cx - r)), int(max(0, cy - r)), int(min(img.width, cx + r)),
                     int(min(img.height, cy + r))))
