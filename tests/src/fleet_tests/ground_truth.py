"""Shared cells against the simulator's ground truth (issue 26): precision and face recall.

The simulator knows where every object that is not on the map stands (the blocks of a goals file,
or what a scenario added). A shared cell "lies on" an object when its square (a costmap cell)
touches the object's rectangle. Precision is the share of the cells robots marked in their fleet
messages that lie on an object; recall is the share of an object's visible face (the side facing
the robot that shared it, between the walls it reaches into) that some shared cell covers. Pure
functions: tests/test/test_ground_truth.py."""
import math


def block_corners(block):
    """The four corners (x, y) of a block {"pose": [x, y, yaw], "size": [sx, sy]}, counterclockwise."""
    (bx, by, yaw), (sx, sy) = block["pose"], block["size"]
    c, s = math.cos(yaw), math.sin(yaw)
    return [(bx + c * dx - s * dy, by + s * dx + c * dy)
            for dx, dy in ((-sx / 2, -sy / 2), (sx / 2, -sy / 2), (sx / 2, sy / 2), (-sx / 2, sy / 2))]


def distance_to_block(x, y, block):
    """Metres from (x, y) to the block's rectangle (0 inside)."""
    (bx, by, yaw), (sx, sy) = block["pose"], block["size"]
    c, s = math.cos(yaw), math.sin(yaw)
    u = c * (x - bx) + s * (y - by)        # the point in the block's own frame
    v = -s * (x - bx) + c * (y - by)
    du = max(abs(u) - sx / 2, 0.0)
    dv = max(abs(v) - sy / 2, 0.0)
    return math.hypot(du, dv)


# Stage (and fleet_sim) rasterise every model on the world's grid (make_facility_world writes `resolution 0.02`),
# filling each raster cell the model touches, and a beam stops at the first filled one: a beam can end up to one
# raster cell's diagonal outside the model's nominal rectangle (seen at the blocks' corners, 0.035-0.039 m from
# them with the costmap's 0.05 m cells). The misplacements this rule exists to catch are 0.075 m and more.
SIMULATOR_RASTER = 0.02


def on_block(x, y, resolution, block, raster=SIMULATOR_RASTER):
    """Whether the cell centred at (x, y) touches the block as the simulator draws it: within half a cell's
    diagonal plus one raster cell's diagonal of its rectangle."""
    return distance_to_block(x, y, block) <= (resolution * math.sqrt(0.5) + raster * math.sqrt(2.0)) + 1e-9


def precision(cells, resolution, blocks):
    """(share on an object, [cells on none]) of cells [(x, y)], each counted once; (nan, []) for none."""
    unique = sorted(set((round(x, 4), round(y, 4)) for x, y in cells))
    if not unique:
        return float("nan"), []
    off = [(x, y) for x, y in unique if not any(on_block(x, y, resolution, b) for b in blocks)]
    return 1.0 - len(off) / float(len(unique)), off


def visible_face(block, viewer):
    """(a, b): the end points of the block side whose outward normal points most towards viewer (x, y)."""
    corners = block_corners(block)
    (bx, by, _yaw) = block["pose"]
    best, best_dot = None, -float("inf")
    for k in range(4):
        a, b = corners[k], corners[(k + 1) % 4]
        mx, my = (a[0] + b[0]) / 2, (a[1] + b[1]) / 2
        nx, ny = mx - bx, my - by                       # outward: from the centre through the side's middle
        norm = math.hypot(nx, ny) or 1.0
        dot = (nx * (viewer[0] - mx) + ny * (viewer[1] - my)) / norm
        if dot > best_dot:
            best, best_dot = (a, b), dot
    return best


def face_recall(cells, resolution, block, viewer, free=lambda x, y: True, step=None):
    """Share of the visible face (towards viewer) that shared cells cover: points every `step` m (default
    one cell) along the face, those where free(x, y) holds (a caller leaves out the stretch inside the walls
    and within static_tolerance of them: never shareable), each covered when a shared cell's square holds it
    or touches it. (nan, []) when no face point is free; else (recall, [points not covered])."""
    step = step or resolution
    (ax, ay), (bx, by) = visible_face(block, viewer)
    length = math.hypot(bx - ax, by - ay)
    n = max(1, int(length / step))
    points = [(ax + (bx - ax) * (k + 0.5) / n, ay + (by - ay) * (k + 0.5) / n) for k in range(n)]
    points = [p for p in points if free(*p)]
    if not points:
        return float("nan"), []
    half = resolution / 2 + 1e-6
    reach = resolution  # a cell on the face or the one in front of it (the face line lies on a cell border)
    missed = [(px, py) for px, py in points
              if not any(abs(px - x) <= half + reach / 2 and abs(py - y) <= half + reach / 2 for x, y in cells)]
    return 1.0 - len(missed) / float(len(points)), missed


def run_figures(messages, tracks, blocks, corridors, margin, walls=None):
    """Precision over every cell the robots sent, and face recall per block someone shared.

    messages: [(sim time, source robot, resolution, [(x, y) of each marked cell])] of the robots' own fleet
    messages; tracks: name -> [(t, x, y)]; blocks: name -> block; corridors: name -> [min_x, min_y, max_x, max_y]
    (a block's face counts between its corridor's walls, `margin` m in from each: never shareable nearer);
    walls: the a-priori map's occupied cells (bench.OccupancyIndex) or None: face points within `margin` of one
    do not count either (a block in a door narrower than its corridor reaches into the door's jambs);
    the viewer of a block is its sharer where it first sent a cell on it.
    {"cells": n, "precision": p, "off": [first cells on no object], "recall": {block: r}}."""
    from fleet_tests.bench import pose_at
    cells = [c for _t, _s, _res, points in messages for c in points]
    resolution = messages[0][2] if messages else 0.05
    value, off = precision(cells, resolution, list(blocks.values()))
    recall = {}
    for name, block in sorted(blocks.items()):
        first = [(t, source, p) for t, source, res, points in messages for p in points
                 if on_block(p[0], p[1], res, block)]
        if not first:
            continue
        t, source, _p = min(first)
        viewer = pose_at(tracks.get(source, []), t)
        if viewer is None:
            continue
        # The layouts' corridors run along y, and a block closes one across its width.
        x0, _y0, x1, _y1 = corridors.get(block.get("corridor"), (-float("inf"), 0.0, float("inf"), 0.0))

        def free(x, y, x0=x0, x1=x1):
            return x0 + margin < x < x1 - margin and (walls is None or not walls.near(x, y, margin))

        recall[name] = round(face_recall(cells, resolution, block, viewer, free=free)[0], 4)
    return {"cells": len(set(cells)), "precision": round(value, 4) if value == value else value,
            "off": off[:20], "recall": recall}
