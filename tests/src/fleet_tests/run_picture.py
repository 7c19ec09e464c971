"""A picture of one scenario run: the a-priori map, the blocks that are not on it, the cells the
fleet shared, and every robot's ground-truth trail. Made from what a scenario node already holds
(the /map message, the facility description, the robots' tracks and shares), so it works the same
on the real stack (stageros, move_base) and on the stand-in.

    draw_run(path, grid, facility, trails, shared, title)

grid: nav_msgs/OccupancyGrid; facility: scenario.load_facility()'s dict; trails: {name: [(t, x, y)]};
shared: SharedObstacle messages (their marked cells are drawn). Raises ValueError on a map it cannot
draw (no cells, bad resolution) rather than writing a misleading picture.

    draw_costmap(path, costmap, title)

One robot's view: its global costmap (nav_msgs/OccupancyGrid as move_base publishes it: 100 lethal,
99 inscribed, 1..98 inflated, 0 free, -1 unknown), for the pictures a failed scenario names.
"""
from PIL import Image, ImageDraw

from fleet_tests.ground_truth import block_corners

# One colour per robot (robot_0 first), readable on the grey map.
TRAIL_COLOURS = [(31, 119, 180), (255, 127, 14), (44, 160, 44), (148, 103, 189), (140, 86, 75),
                 (227, 119, 194), (127, 127, 127), (188, 189, 34), (23, 190, 207), (214, 39, 40)]
SHARED = (220, 20, 60)
BLOCK = (0, 0, 0)


def draw_run(path, grid, facility, trails, shared, title, pixels_per_metre=40):
    info = grid.info
    if info.width <= 0 or info.height <= 0 or not info.resolution > 0 or len(grid.data) != info.width * info.height:
        raise ValueError("cannot draw the run: map of %d x %d cells at %r m with %d values"
                         % (info.width, info.height, info.resolution, len(grid.data)))
    scale = max(1, int(round(pixels_per_metre * info.resolution)))
    ox, oy, res = info.origin.position.x, info.origin.position.y, info.resolution
    w, h = info.width * scale, info.height * scale
    header = 36  # title on the first line, legend on the second
    image = Image.new("RGB", (w, h + header), "white")
    draw = ImageDraw.Draw(image)

    def px(x, y):
        return (x - ox) / res * scale, header + h - (y - oy) / res * scale

    for iy in range(info.height):
        row = grid.data[iy * info.width:(iy + 1) * info.width]
        for ix, v in enumerate(row):
            if v == 0:
                continue
            colour = (205, 205, 205) if v < 0 else (60, 60, 60)
            x0, y1 = ix * scale, header + h - iy * scale
            draw.rectangle([x0, y1 - scale, x0 + scale - 1, y1 - 1], fill=colour)
    for name, block in sorted(facility.get("blocks", {}).items()):
        pose = [float(v) for v in block["pose"]] + [0.0] * (3 - len(block["pose"]))
        corners = [px(x, y) for x, y in block_corners({"pose": pose[:3], "size": block["size"]})]
        draw.polygon(corners, outline=BLOCK, width=2)
        top = min(corners, key=lambda c: c[1])
        draw.text((min(c[0] for c in corners), top[1] - 12), "%s (not on the map)" % name, fill=BLOCK)
    cell_px = max(2, int(round(scale * 1.0)))
    for msg in shared:
        for index in msg.marked_indexes:
            ix, iy = index % msg.size_x, index // msg.size_x
            x, y = px(msg.origin_x + (ix + 0.5) * msg.resolution, msg.origin_y + (iy + 0.5) * msg.resolution)
            draw.rectangle([x - cell_px, y - cell_px, x + cell_px, y + cell_px], fill=SHARED)
    legend = []
    for k, (name, track) in enumerate(sorted(trails.items())):
        colour = TRAIL_COLOURS[k % len(TRAIL_COLOURS)]
        points = [px(x, y) for _t, x, y in track]
        if len(points) > 1:
            draw.line(points, fill=colour, width=3)
        if points:
            draw.ellipse([points[-1][0] - 5, points[-1][1] - 5, points[-1][0] + 5, points[-1][1] + 5], fill=colour)
        legend.append((name, colour))
    draw.text((4, 4), title, fill=(0, 0, 0))
    x = 4
    for name, colour in legend + [("shared cells", SHARED)]:
        draw.rectangle([x, 21, x + 10, 29], fill=colour)
        draw.text((x + 13, 18), name, fill=colour)
        x += 7 * len(name) + 30
    image.save(path)
    return path


def draw_costmap(path, costmap, title, pixels_per_metre=40):
    info = costmap.info
    if info.width <= 0 or info.height <= 0 or not info.resolution > 0 or \
            len(costmap.data) != info.width * info.height:
        raise ValueError("cannot draw the costmap: %d x %d cells at %r m with %d values"
                         % (info.width, info.height, info.resolution, len(costmap.data)))
    scale = max(1, int(round(pixels_per_metre * info.resolution)))
    header = 20
    image = Image.new("RGB", (info.width * scale, info.height * scale + header), "white")
    draw = ImageDraw.Draw(image)
    h = info.height * scale
    for iy in range(info.height):
        row = costmap.data[iy * info.width:(iy + 1) * info.width]
        for ix, v in enumerate(row):
            if v == 0:
                continue
            if v < 0:
                colour = (205, 205, 205)
            elif v >= 99:
                colour = (0, 0, 0) if v == 100 else (90, 30, 120)
            else:
                shade = int(255 - 150 * v / 98.0)
                colour = (255, shade, shade)
            x0, y1 = ix * scale, header + h - iy * scale
            draw.rectangle([x0, y1 - scale, x0 + scale - 1, y1 - 1], fill=colour)
    draw.text((4, 4), "%s (black: lethal, purple: inscribed, red: inflated, grey: unknown)" % title, fill=(0, 0, 0))
    image.save(path)
    return path
