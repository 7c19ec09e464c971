"""What a replay produced: the summary (a dict, also as text) and the PNG of the map."""
import math

import numpy as np

LETHAL = 254

# Exit-code bits for a replay that ran (README, "Offline bag replay").
EXIT_OK = 0
EXIT_INTERNAL = 1
EXIT_USAGE = 2          # bad command line, parameters or map: nothing replayed
EXIT_BAG_UNREADABLE = 3  # the bag cannot be opened at all
EXIT_NO_SCANS = 4        # no LaserScan topic to replay (missing topic)
BIT_BAG_DAMAGED = 8      # truncated/unindexed bag, unreadable chunks, messages that do not deserialise
BIT_TF = 16              # scans dropped for tf (gap, extrapolation, frame not connected to the global frame), or
#                          a robot of the bag never found in tf (so the others' layers could not exclude it)
BIT_INPUT = 32           # a trigger or tf topic missing, scans with bad content, tf with bad values

_BAG_COUNTERS = ("bag_unindexed", "damaged_chunks", "lost_messages", "bad_message")
_TF_COUNTERS = ("scans_tf_gap", "scans_tf_extrapolation", "scans_tf_unconnected", "robots_never_placed")
_INPUT_COUNTERS = ("scans_bad", "tf_rejected")


def exit_code(replay):
    code = EXIT_OK
    p = replay.problems
    if any(p.get(k) for k in _BAG_COUNTERS):
        code |= BIT_BAG_DAMAGED
    if any(p.get(k) for k in _TF_COUNTERS):
        code |= BIT_TF
    if replay.missing_topics or any(p.get(k) for k in _INPUT_COUNTERS):
        code |= BIT_INPUT
    return code


def near_wall_mask(static, distance):
    """Cells within `distance` cells (Chebyshev) of a static wall cell."""
    return grow_mask(static >= LETHAL, distance)


def grow_mask(mask, distance):
    """Cells within `distance` cells (Chebyshev) of a cell of mask."""
    if distance <= 0:
        return mask
    out = mask.copy()
    for axis in (0, 1):
        grown = out.copy()
        n = out.shape[axis]
        for shift in range(1, distance + 1):
            if shift >= n:
                break
            lo = [slice(None)] * 2
            hi = [slice(None)] * 2
            lo[axis], hi[axis] = slice(shift, None), slice(None, -shift)
            grown[tuple(lo)] |= out[tuple(hi)]
            grown[tuple(hi)] |= out[tuple(lo)]
        out = grown
    return out


def summarise(replay, bag_path):
    s = replay.settings
    # A false share lies within wall_distance cells of a cell the a-priori map marks occupied, or of
    # one it leaves unknown (where Stage may be solid although the map says nothing).
    near_occupied = near_wall_mask(replay.static, s.wall_distance).reshape(-1)
    near_unknown = grow_mask(np.asarray(replay.map.occupancy) == -1, s.wall_distance).reshape(-1)
    near = near_occupied | near_unknown
    obstacles = []
    cells_total = cells_near = all_near = cells_near_occupied = cells_near_unknown = 0
    for uuid, rec in sorted(replay.obstacles.items(), key=lambda item: (item[1]["time"], item[0])):
        ever = np.fromiter(rec["cell_time"].keys(), dtype=np.int64, count=len(rec["cell_time"]))
        n_near = int(near[ever].sum()) if ever.size else 0
        n_occupied = int(near_occupied[ever].sum()) if ever.size else 0
        n_unknown = int(near_unknown[ever].sum()) if ever.size else 0
        cells_total += int(ever.size)
        cells_near += n_near
        cells_near_occupied += n_occupied
        cells_near_unknown += n_unknown
        if ever.size and n_near == ever.size:
            all_near += 1
        obstacles.append({
            "uuid": uuid, "robot": rec["robot"], "time": round(rec["time"], 3),
            "t": round(rec["time"] - replay.start_time, 3),
            "rectangle": [round(v, 4) for v in rec["rectangle"]], "cells_ever": int(ever.size),
            "cells_final": int(ever.size - len(rec["cleared"])), "cells_near_walls": n_near,
            "cells_near_occupied": n_occupied, "cells_near_unknown": n_unknown,
            "updates": rec["updates"],
            "ever_indexes": sorted(int(c) for c in rec["cell_time"]),
            "final_indexes": sorted(int(c) for c in rec["cell_time"] if c not in rec["cleared"])})
    events = replay.event_counts
    duration = max(0.0, replay.end_time - replay.start_time)
    wall = max(replay.wall_seconds, 1e-9)
    summary = {
        "bag": bag_path,
        "bag_duration_s": round(duration, 3),
        "map": replay.map.source if replay.map is not None else None,
        "robots": sorted(r.name for r in replay.robots.values()),
        "obstacles_shared": len(replay.obstacles),
        "proposals": events.get("proposal", 0),
        "merged_proposals": sum(r.handler.counters["merged_proposals"] for r in replay.robots.values()),
        "triggers": events.get("trigger", 0),
        "plan_triggers": events.get("plan_trigger", 0),
        "plans": events.get("plan", 0),
        "updates": events.get("update", 0),
        "received": events.get("received", 0),
        "expiries": events.get("expiry", 0),
        "cells_shared": cells_total,
        "fleet_messages": replay.fleet_messages,
        "bytes_plain": replay.bytes_plain,
        "bytes_compact": replay.bytes_compact,
        "compact_to_plain": round(replay.bytes_compact / replay.bytes_plain, 4) if replay.bytes_plain else None,
        "false_shares": {"wall_distance_cells": s.wall_distance, "cells_near_walls": cells_near,
                         "cells_near_occupied": cells_near_occupied, "cells_near_unknown": cells_near_unknown,
                         "cells": cells_total, "obstacles_all_near_walls": all_near},
        "scans_processed": replay.scans,
        "scans_dropped": sum(r.scans_dropped for r in replay.robots.values()),
        "messages": replay.messages,
        "wall_seconds": round(wall, 3),
        "scans_per_second": round(replay.scans / wall, 1),
        "real_time_factor": round(duration / wall, 2) if duration > 0 else None,
        "problems": dict(sorted(replay.problems.items())),
        "frames_failed": {k: dict(v) for k, v in replay.frames_failed.items()},
        "missing_topics": list(replay.missing_topics),
        "notes": {k: list(v) for k, v in replay.notes.items()},
        "parameters": {"layer": dict(s.layer), "obstacle_duration": s.obstacle_duration,
                       "tf_max_gap": s.tf_max_gap, "tf_tolerance": s.tf_tolerance, "trigger": s.trigger,
                       "plan_topics": list(s.plan_topics)},
        "obstacles": obstacles,
        "trigger_sources": {name: list(found) for name, found in sorted(replay.trigger_sources.items())},
        "robot_exclusion": robot_exclusion(replay),
    }
    summary["exit_code"] = exit_code(replay)
    return summary


def robot_exclusion(replay):
    """Which of the bag's robots every layer excluded, with which footprint, and how often one had no pose."""
    others = replay.others
    if others is None:
        return {"on": replay.settings.robot_exclusion, "robots": {}}
    return {"on": True, "margin": replay.settings.robot_exclusion_margin, "timeout": replay.settings.robot_timeout,
            "trail": replay.settings.robot_exclusion_trail,
            "robots": {name: others.footprint_source(name) for name in sorted(others.frames)},
            "unplaced_scans": dict(sorted(others.unplaced.items()))}


def summary_text(summary):
    fs = summary["false_shares"]
    lines = [
        "bag: %s (%.1f s, robots %s)" % (summary["bag"], summary["bag_duration_s"], ", ".join(summary["robots"])),
        "obstacles shared: %d (proposals %d, merged into a live obstacle %d, triggers %d, plan triggers %d)" % (
            summary["obstacles_shared"], summary["proposals"], summary["merged_proposals"], summary["triggers"],
            summary["plan_triggers"]),
        "updates: %d, received by other robots: %d, expiries: %d" % (
            summary["updates"], summary["received"], summary["expiries"]),
        "cells shared: %d; near walls (within %d cells of an occupied or unknown map cell): %d cells (%d near "
        "occupied, %d near unknown), %d obstacle(s) entirely" % (
            summary["cells_shared"], fs["wall_distance_cells"], fs["cells_near_walls"], fs["cells_near_occupied"],
            fs["cells_near_unknown"], fs["obstacles_all_near_walls"]),
        "fleet traffic: %d messages, %d bytes plain, %d bytes compact (ratio %s)" % (
            summary["fleet_messages"], summary["bytes_plain"], summary["bytes_compact"], summary["compact_to_plain"]),
        "scans: %d processed, %d dropped; %.0f scans/s, real-time factor %s (%.2f s wall)" % (
            summary["scans_processed"], summary["scans_dropped"], summary["scans_per_second"],
            summary["real_time_factor"], summary["wall_seconds"]),
    ]
    exclusion = summary["robot_exclusion"]
    if exclusion["robots"]:
        groups = [(label, [r for r, source in exclusion["robots"].items() if source == key])
                  for key, label in (("recorded footprint", "footprint recorded"),
                                     ("parameters", "footprint of the parameters"))]
        lines.append("other robots never shared: %s (placed from tf; %s; margin %g m, trail %g s)" % (
            ", ".join(exclusion["robots"]), "; ".join("%s: %s" % (label, ", ".join(names))
                                                       for label, names in groups if names), exclusion["margin"],
            exclusion["trail"]))
    elif not exclusion["on"]:
        lines.append("other robots: NOT excluded (--no-robot-exclusion): robots in view may be shared")
    silent = [name for name, found in summary["trigger_sources"].items() if not found]
    if silent:
        lines.append("no trigger or plan in the bag for %s: nothing can be proposed from %s" % (
            ", ".join(silent), "it" if len(silent) == 1 else "them"))
    for obstacle in summary["obstacles"]:
        lines.append("  %s %s t=%.1f s rect %s: %d cells (%d now), %d near walls, %d updates" % (
            obstacle["uuid"][:8], obstacle["robot"], obstacle["t"], obstacle["rectangle"], obstacle["cells_ever"],
            obstacle["cells_final"], obstacle["cells_near_walls"], obstacle["updates"]))
    if summary["problems"] or summary["missing_topics"]:
        lines.append("problems: %s" % ", ".join("%s=%d" % kv for kv in summary["problems"].items()))
        for topic in summary["missing_topics"]:
            lines.append("  missing topic: %s" % topic)
        for reason, frames in summary["frames_failed"].items():
            lines.append("  %s: %s" % (reason, ", ".join("%s x%d" % kv for kv in sorted(frames.items()))))
    for counter, notes in summary["notes"].items():
        for note in notes[:3]:
            lines.append("  %s" % note)
    lines.append("exit code: %d" % summary["exit_code"])
    return "\n".join(lines)


_RAMP = np.array([[49, 54, 149], [69, 117, 180], [116, 173, 209], [171, 217, 233], [254, 224, 144],
                  [253, 174, 97], [244, 109, 67], [215, 48, 39], [165, 0, 38]], dtype=np.float64)


def time_colour(fraction):
    """Blue (start of the bag) -> red (end)."""
    f = min(1.0, max(0.0, fraction if math.isfinite(fraction) else 0.0)) * (len(_RAMP) - 1)
    i = min(int(f), len(_RAMP) - 2)
    c = _RAMP[i] + (_RAMP[i + 1] - _RAMP[i]) * (f - i)
    return tuple(int(round(v)) for v in c)


def render_png(replay, path, scale=None):
    """The map with every shared obstacle: cells filled in the colour of the time they were first
    shared (cleared cells only outlined), rectangles in the colour of the share time, robot paths
    grey, and a time bar. Returns (width, height)."""
    from PIL import Image, ImageDraw
    m = replay.map
    occ = m.occupancy
    if scale is None:
        scale = max(1, int(math.ceil(1000.0 / max(m.size_x, m.size_y))))
    grey = np.full(occ.shape, 205, dtype=np.uint8)
    grey[occ == 0] = 255
    grey[(occ > 0) & (occ < 100)] = 180
    grey[replay.static >= LETHAL] = 40
    img = Image.fromarray(grey[::-1], mode="L").convert("RGB")
    if scale > 1:
        img = img.resize((m.size_x * scale, m.size_y * scale), Image.NEAREST)
    bar = 40
    canvas = Image.new("RGB", (img.width, img.height + bar), (255, 255, 255))
    canvas.paste(img, (0, 0))
    draw = ImageDraw.Draw(canvas)
    height = m.size_y * scale
    duration = max(replay.end_time - replay.start_time, 1e-9)

    def px(x, y):
        return ((x - m.origin_x) / m.resolution * scale, height - (y - m.origin_y) / m.resolution * scale)

    for robot in replay.robots.values():
        if len(robot.path) > 1:
            draw.line([px(x, y) for x, y in robot.path], fill=(150, 150, 150), width=1)
    for uuid, rec in sorted(replay.obstacles.items(), key=lambda item: item[1]["time"]):
        for cell, t in rec["cell_time"].items():
            cx, cy = cell % m.size_x, cell // m.size_x
            x0, y0 = cx * scale, height - (cy + 1) * scale
            colour = time_colour((t - replay.start_time) / duration)
            box = [x0, y0, x0 + scale - 1, y0 + scale - 1]
            if cell in rec["cleared"]:
                draw.rectangle(box, outline=colour)
            else:
                draw.rectangle(box, fill=colour)
        # The rectangle in a darker shade of its share-time colour, just outside its cells.
        colour = tuple(int(v * 0.6) for v in time_colour((rec["time"] - replay.start_time) / duration))
        x0, y1 = px(rec["rectangle"][0], rec["rectangle"][1])
        x1, y0 = px(rec["rectangle"][2], rec["rectangle"][3])
        draw.rectangle([x0 - 2, y0 - 2, x1 + 1, y1 + 1], outline=colour, width=1)
        draw.text((x1 + 3, y0), "%s %.0fs" % (uuid[:6], rec["time"] - replay.start_time), fill=colour)
    # Time bar.
    top = img.height + 8
    width = img.width - 20
    for i in range(width):
        draw.line([(10 + i, top), (10 + i, top + 10)], fill=time_colour(i / max(1, width - 1)))
    draw.text((10, top + 13), "t = 0 s", fill=(0, 0, 0))
    draw.text((max(10, img.width - 90), top + 13), "t = %.0f s" % duration, fill=(0, 0, 0))
    canvas.save(path)
    return canvas.size
