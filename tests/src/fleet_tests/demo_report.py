"""make demo's report: the same dispatch with sharing on and off, side by side (scripts/run_demo.py runs it).

Pure: it reads the two runs' results (fleet_tests.bench's JSON: dispatch, times to goal, ground-truth tracks,
what was shared and when each robot knew of the block) and the map, and writes Markdown and pictures. Every
number it prints is a number; where a figure cannot be given the cell says why. Tested without ROS
(tests/test/test_demo_report.py).
"""
import math
import re

from PIL import Image, ImageDraw, ImageFont

from fleet_tests.ground_truth import block_corners

# One colour per robot (robot_0 first), readable on the grey map and apart from the red of shared cells.
ROBOT_COLOURS = [(31, 119, 180), (44, 160, 44), (148, 103, 189), (255, 127, 14), (140, 86, 75),
                 (227, 119, 194), (127, 127, 127), (188, 189, 34), (23, 190, 207), (0, 0, 128)]
SHARED = (220, 20, 60)
BLOCK = (0, 0, 0)


class ReportError(Exception):
    """The runs' results cannot make a report (a run without results, a robot missing): says which."""


def _font(size):
    try:
        return ImageFont.truetype("DejaVuSans.ttf", size)
    except OSError:
        return ImageFont.load_default()


def path_length(track):
    return sum(math.hypot(b[1] - a[1], b[2] - a[2]) for a, b in zip(track, track[1:]))


def _finite(value):
    return isinstance(value, (int, float)) and math.isfinite(value)


def compare(on, off, blocked):
    """Per robot, in dispatch order: {robot, sent (s after the first dispatch), time_on, time_off, path_on, path_off,
    entered_on, entered_off, knew_on (s after the first dispatch; None: never)}. `blocked` names the blocked
    corridors (entered_per_robot's names; one name or several). Raises ReportError naming what is missing."""
    blocked = {blocked} if isinstance(blocked, str) else set(blocked)
    for name, run in (("sharing on", on), ("sharing off", off)):
        if not run:
            raise ReportError("the run with %s gave no result" % name)
    order = [d["robot"] for d in on["dispatch"]]
    if order != [d["robot"] for d in off["dispatch"]]:
        raise ReportError("the two runs dispatched differently: %s against %s"
                          % (order, [d["robot"] for d in off["dispatch"]]))
    first = {id(run): min(d["sent_at"] for d in run["dispatch"]) for run in (on, off)}
    rows = []
    for name in order:
        sent_on = next(d["sent_at"] for d in on["dispatch"] if d["robot"] == name)
        sent_off = next(d["sent_at"] for d in off["dispatch"] if d["robot"] == name)
        knew = (on.get("knew_block") or {}).get(name)
        rows.append({
            "robot": name,
            "sent": sent_on - first[id(on)],
            "sent_off": sent_off - first[id(off)],
            "time_on": on["time_to_goal"].get(name),
            "time_off": off["time_to_goal"].get(name),
            "path_on": path_length(_after(on["tracks"].get(name, []), sent_on)),
            "path_off": path_length(_after(off["tracks"].get(name, []), sent_off)),
            "entered_on": bool(blocked & set(on["entered_per_robot"].get(name, []))),
            "entered_off": bool(blocked & set(off["entered_per_robot"].get(name, []))),
            "knew_on": knew - first[id(on)] if _finite(knew) else None,
        })
    return rows


def _after(track, t):
    return [p for p in track if p[0] >= t]


def first_share(run):
    """(robot, s after the first dispatch, cells) of the first message that shared a cell, or None."""
    shares = sorted(run.get("shares") or [], key=lambda s: s["t"])
    if not shares:
        return None
    first = min(d["sent_at"] for d in run["dispatch"])
    return shares[0]["robot"], shares[0]["t"] - first, len(shares[0]["cells"])


def totals(rows):
    """Means over the robots that reached their goal in both runs, and the counts."""
    both = [r for r in rows if _finite(r["time_on"]) and _finite(r["time_off"])]
    mean_on = sum(r["time_on"] for r in both) / len(both) if both else float("nan")
    mean_off = sum(r["time_off"] for r in both) / len(both) if both else float("nan")
    return {"both": len(both), "mean_on": mean_on, "mean_off": mean_off,
            "ratio": mean_on / mean_off if both and mean_off > 0 else float("nan"),
            "path_on": sum(r["path_on"] for r in rows), "path_off": sum(r["path_off"] for r in rows),
            "entered_on": sum(r["entered_on"] for r in rows), "entered_off": sum(r["entered_off"] for r in rows),
            "reached_on": sum(_finite(r["time_on"]) for r in rows),
            "reached_off": sum(_finite(r["time_off"]) for r in rows), "robots": len(rows)}


def _seconds(value, missing):
    return "%.1f s" % value if _finite(value) else missing


def _named(blocked):
    names = [blocked] if isinstance(blocked, str) else sorted(blocked)
    return ("the blocked %s corridor" % names[0]) if len(names) == 1 else \
        ("a blocked corridor (%s)" % " or ".join(names))


def markdown(rows, on, off, settings, pictures, blocked):
    """The report's Markdown: the comparison first, then the pictures and the settings."""
    t = totals(rows)
    share = first_share(on)
    lines = ["# Fleet demo: sharing on against off, upstream move_base on Stage", ""]
    if t["both"]:
        lines.append("**With sharing the robots reached their goals in %.2f × the time without** (mean %.1f s "
                     "against %.1f s over the %d robots that arrived in both runs); %d of %d robots drove into %s "
                     "with sharing, %d without." % (
                         t["ratio"], t["mean_on"], t["mean_off"], t["both"], t["entered_on"], t["robots"],
                         _named(blocked), t["entered_off"]))
    else:
        lines.append("**No robot reached its goal in both runs**: no time ratio (see the table).")
    lines.append("")
    if share:
        lines.append("The block was first shared by %s %.1f s after the first dispatch (%d cells); every robot's "
                     "layer held it from the time in the last column on." % share)
    else:
        lines.append("Nothing was shared in the run with sharing on.")
    lines += ["", "| robot | sent (s after the first) | time to goal on / off | path on / off | drove into %s "
              "on / off | knew of the block (s after the first dispatch) |" % _named(blocked),
              "|---|---|---|---|---|---|"]
    for r in rows:
        lines.append("| %s | %.1f | %s / %s | %.1f m / %.1f m | %s / %s | %s |" % (
            r["robot"], r["sent"], _seconds(r["time_on"], "not reached"), _seconds(r["time_off"], "not reached"),
            r["path_on"], r["path_off"], "yes" if r["entered_on"] else "no", "yes" if r["entered_off"] else "no",
            _seconds(r["knew_on"], "never (nothing on the block reached its layer)")))
    lines += ["", "Times are simulated seconds from a robot's dispatch to its first ground-truth pose within 0.3 m of "
              "its goal; paths are ground truth (Stage) from the dispatch on. Reached: %d/%d with sharing, %d/%d "
              "without." % (t["reached_on"], t["robots"], t["reached_off"], t["robots"]), ""]
    lines += ["## The paths", "", "![paths with sharing on and off](%s)" % pictures["paths"], "",
              "Each robot's ground-truth path in its colour (a ring where it started, a dot where it ended), the block "
              "that is not on the map in black, and in red every cell the robots shared (left only).", "",
              "## The timeline", "", "![timeline](%s)" % pictures["timeline"], "",
              "Per robot: from dispatch to arrival, the stretch in the blocked corridor, when the robot knew of the "
              "block (diamond) and the first share (star).", "", "## Settings", ""]
    lines += ["- " + s for s in settings]
    lines += ["- simulated s per wall s: %s with sharing, %s without" % (
        "%.2f" % on["realtime_factor"] if _finite(on.get("realtime_factor")) else "not measured",
        "%.2f" % off["realtime_factor"] if _finite(off.get("realtime_factor")) else "not measured")]
    return "\n".join(lines) + "\n"


def _map_image(grid, scale):
    """The a-priori map (fleet_sim.map_io.OccupancyMap: data rows y up, 100 occupied, -1 unknown) as an RGB image."""
    import numpy as np
    data = np.asarray(grid.data)
    rgb = np.full(data.shape + (3,), 255, dtype=np.uint8)
    rgb[data > 0] = (90, 90, 90)
    rgb[data < 0] = (205, 205, 205)
    rgb = np.repeat(np.repeat(rgb[::-1], scale, axis=0), scale, axis=1)  # rows y down, each cell scale px
    return Image.fromarray(rgb, "RGB")


def draw_paths(path, grid, blocks, on, off, pixels_per_metre=30):
    """Two panels, sharing on (with the shared cells) and off: the map, the blocks, each robot's path."""
    scale = max(1, int(round(pixels_per_metre * grid.resolution)))
    ppm = scale / grid.resolution
    panel_w, panel_h = grid.width * scale, grid.height * scale
    header, gap = 64, 24
    image = Image.new("RGB", (2 * panel_w + gap, panel_h + header), "white")
    draw = ImageDraw.Draw(image)
    big, small = _font(18), _font(13)
    base = _map_image(grid, scale)
    robots = [d["robot"] for d in on["dispatch"]]
    for k, (title, run) in enumerate((("sharing on", on), ("sharing off", off))):
        x0 = k * (panel_w + gap)
        image.paste(base, (x0, header))

        def px(x, y, x0=x0):
            return x0 + (x - grid.origin[0]) * ppm, header + panel_h - (y - grid.origin[1]) * ppm
        for b in blocks:
            draw.polygon([px(x, y) for x, y in block_corners(b)], fill=BLOCK)
        for name in robots:
            colour = ROBOT_COLOURS[int(name.rsplit("_", 1)[-1]) % len(ROBOT_COLOURS)]
            track = run["tracks"].get(name, [])
            points = [px(x, y) for _t, x, y in track]
            if len(points) > 1:
                draw.line(points, fill=colour, width=3)
            if points:
                (sx, sy), (ex, ey) = points[0], points[-1]
                draw.ellipse([sx - 6, sy - 6, sx + 6, sy + 6], outline=colour, width=3)
                draw.ellipse([ex - 5, ey - 5, ex + 5, ey + 5], fill=colour)
        if run is on:  # over the paths: what the fleet was told is what the picture is about
            half = max(1.5, 0.025 * ppm)
            for s in run.get("shares") or []:
                for x, y in s["cells"]:
                    cx, cy = px(x, y)
                    draw.rectangle([cx - half, cy - half, cx + half, cy + half], fill=SHARED)
        draw.text((x0 + 4, 6), title, fill=(0, 0, 0), font=big)
    # one legend for both panels, on its own line: names never overlap the map or each other
    x = 4
    for name in robots + ["shared cells", "block"]:
        colour = SHARED if name == "shared cells" else BLOCK if name == "block" else \
            ROBOT_COLOURS[int(name.rsplit("_", 1)[-1]) % len(ROBOT_COLOURS)]
        draw.rectangle([x, 38, x + 14, 52], fill=colour)
        draw.text((x + 18, 37), name, fill=(0, 0, 0), font=small)
        x += 18 + int(draw.textlength(name, font=small)) + 20
    image.save(path)
    return path


def draw_timeline(path, rows, on, off, blocked_spans):
    """Per robot two lanes (on, off): dispatch to arrival, the stretch in the blocked corridor (hatched), when it
    knew of the block (diamond) and the first share (star). blocked_spans: {(robot, sharing): [(t0, t1)]} in s
    after the first dispatch."""
    end = 10.0
    for r in rows:
        for key, sent in (("time_on", r["sent"]), ("time_off", r["sent_off"])):
            if _finite(r[key]):
                end = max(end, sent + r[key])
    end *= 1.05
    left, right, lane, top = 150, 30, 22, 50
    width = 900
    height = top + len(rows) * 2 * lane + len(rows) * 10 + 40
    image = Image.new("RGB", (width, height), "white")
    draw = ImageDraw.Draw(image)
    font = _font(13)
    scale = (width - left - right) / end

    def tx(t):
        return left + t * scale
    draw.text((4, 4), "seconds after the first dispatch (simulated)", fill=(0, 0, 0), font=font)
    for t in range(0, int(end) + 1, 10 if end < 200 else 30):
        draw.line([tx(t), top - 8, tx(t), height - 30], fill=(230, 230, 230))
        draw.text((tx(t) - 8, top - 26), "%d" % t, fill=(0, 0, 0), font=font)
    share = first_share(on)
    y = top
    for r in rows:
        colour = ROBOT_COLOURS[int(r["robot"].rsplit("_", 1)[-1]) % len(ROBOT_COLOURS)]
        for sharing, key, sent in ((True, "time_on", r["sent"]), (False, "time_off", r["sent_off"])):
            draw.text((4, y + 3), "%s %s" % (r["robot"], "on" if sharing else "off"), fill=(0, 0, 0), font=font)
            stop = sent + r[key] if _finite(r[key]) else end
            draw.rectangle([tx(sent), y + 5, tx(stop), y + lane - 5], fill=colour if _finite(r[key]) else (200, 200, 200))
            for t0, t1 in blocked_spans.get((r["robot"], sharing), []):
                draw.rectangle([tx(t0), y + 2, tx(t1), y + lane - 2], outline=(0, 0, 0), width=2)
            if sharing and _finite(r["knew_on"]):
                k = tx(r["knew_on"])
                draw.polygon([(k, y + 2), (k + 6, y + lane / 2), (k, y + lane - 2), (k - 6, y + lane / 2)],
                             fill=(0, 0, 0))
            if sharing and share and share[0] == r["robot"]:
                s = tx(share[1])
                draw.regular_polygon((s, y + lane / 2, 8), 5, fill=SHARED)
            y += lane
        y += 10
    draw.text((4, height - 22), "bar: dispatch to arrival (grey: not reached); black frame: in the blocked corridor; "
              "diamond: knew of the block; red star: first share", fill=(0, 0, 0), font=font)
    image.save(path)
    return path


def blocked_spans(run, corridor):
    """{(robot, sharing): [(t0, t1)]}: stretches (s after the first dispatch) each robot's track spent inside the
    corridor rectangle [min_x, min_y, max_x, max_y]."""
    first = min(d["sent_at"] for d in run["dispatch"])
    out = {}
    for name, track in run["tracks"].items():
        spans, start, last = [], None, None
        for t, x, y in track:
            inside = corridor[0] <= x <= corridor[2] and corridor[1] <= y <= corridor[3]
            if inside and start is None:
                start = t
            if not inside and start is not None:
                spans.append((start - first, last - first))
                start = None
            last = t
        if start is not None:
            spans.append((start - first, last - first))
        out[(name, bool(run.get("sharing")))] = spans
    return out


_NOT_A_NUMBER = re.compile(r"(?<![A-Za-z])(nan|-?inf)(?![A-Za-z])", re.IGNORECASE)


def numbers_missing(text):
    """The lines of a report that print a number that is not one (nan, inf)."""
    return [line for line in text.splitlines() if _NOT_A_NUMBER.search(line)]


def console_section(picture, outcome):
    """The fleet console's part of the report: the screenshot its browser test took during this demo run."""
    text = "\n## The operator's view: the fleet console\n\n"
    text += ("The page a browser shows (`fleet_console`, headless Chromium), taken by its test during this demo on "
             "two robots on the stand-ins: a share listed on the page, a read-only login refused, an operator's "
             "removal dropped by every robot's list and costmap, malformed payloads shown as dropped. Test: %s.\n\n"
             % outcome)
    if picture:
        text += "![the fleet console during the demo](%s)\n" % picture
    return text
