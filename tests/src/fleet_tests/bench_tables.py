"""The fleet bench's tables and chart (tests/scripts/bench_fleet): per run, and per N with sharing on against off
(mean, spread and a 95 % interval of the on/off ratio over the seeds). Rows are (N, sharing, seed, result or None),
a result as fleet_tests.bench writes it."""
import math


def mean_sd(values):
    values = [v for v in values if math.isfinite(v)]
    if not values:
        return float("nan"), float("nan")
    m = sum(values) / len(values)
    sd = math.sqrt(sum((v - m) ** 2 for v in values) / (len(values) - 1)) if len(values) > 1 else 0.0
    return m, sd


def fmt_mean_sd(values, digits=1):
    m, sd = mean_sd(values)
    return "-" if not math.isfinite(m) else "%.*f ± %.*f" % (digits, m, digits, sd)


def ratio_interval(ratios, confidence=0.95):
    """(mean, low, high) of per-seed ratios: Student's t interval over the seeds; (mean, nan, nan) for one seed."""
    values = [r for r in ratios if math.isfinite(r)]
    if not values:
        return float("nan"), float("nan"), float("nan")
    m, sd = mean_sd(values)
    if len(values) < 2:
        return m, float("nan"), float("nan")
    from scipy.stats import t
    half = t.ppf(0.5 + confidence / 2.0, len(values) - 1) * sd / math.sqrt(len(values))
    return m, m - half, m + half


def pooled(rows, n):
    """The figures of N robots over the seeds that have both runs, or None when no seed has: time to goal of every
    robot that reached its goal (``on``, ``off``), their ``ratio``, the per-seed ratio's mean and 95 % interval
    (``per_seed_ratio``), the counts summed over the seeds (``reached``, ``recoveries``, ``crossed``: {sharing:
    total}) and listed per seed (``per_seed(key, sharing)``), the slowest simulator factor, and the ground truth's
    minimum precision and face recall (None when no run measured them)."""
    got = {(s, sh): r for nn, sh, s, r in rows if nn == n and r is not None}
    seeds = sorted({s for s, _sh in got if (s, True) in got and (s, False) in got})
    if not seeds:
        return None
    on = [t for s in seeds for t in got[(s, True)]["time_to_goal"].values()]
    off = [t for s in seeds for t in got[(s, False)]["time_to_goal"].values()]
    (m_on, _), (m_off, _) = mean_sd(on), mean_sd(off)
    truth = [got[(s, True)].get("ground_truth") or {} for s in seeds]
    precisions = [t["precision"] for t in truth if isinstance(t.get("precision"), float) and math.isfinite(t["precision"])]
    recalls = [v for t in truth for v in (t.get("recall") or {}).values()]
    factors = [got[(s, sh)].get("realtime_factor") for s in seeds for sh in (True, False)]
    factors = [f for f in factors if isinstance(f, (int, float)) and math.isfinite(f)]

    def total(key, sharing):
        return sum(got[(s, sharing)].get(key, 0) for s in seeds)
    return {
        "n": n, "seeds": seeds, "got": got, "on": on, "off": off,
        "ratio": m_on / m_off if m_off and math.isfinite(m_on) and math.isfinite(m_off) else float("nan"),
        "per_seed_ratio": ratio_interval([got[(s, True)]["time_mean"] / got[(s, False)]["time_mean"] for s in seeds
                                          if got[(s, False)]["time_mean"]]),
        "factor": min(factors) if factors else None,
        "reached": {sh: total("reached", sh) for sh in (True, False)},
        "recoveries": {sh: total("recoveries", sh) for sh in (True, False)},
        "crossed": {sh: total("entered_blocked_corridor", sh) for sh in (True, False)},
        "precision": min(precisions) if precisions else None,
        "recall": min(recalls) if recalls else None,
        "per_seed": lambda key, sharing: "+".join(str(got[(s, sharing)].get(key, "?")) for s in seeds),
    }


def interval_text(per_seed_ratio):
    mean, low, high = per_seed_ratio
    if math.isfinite(low):
        return "%.2f [%.2f, %.2f]" % per_seed_ratio
    return "%.2f (one seed: no interval)" % mean if math.isfinite(mean) else "-"


def summary(rows):
    """Per N: time to goal (every robot of every seed that reached its goal) with sharing against
    without; the saving per seed (mean off - mean on) shows the spread between seeds; the other
    figures as mean ± sd over the seeds. A robot that gave up has no time to goal: the reached
    column says how many count."""
    lines = ["| N | seeds | time to goal on: mean ± sd s | off: mean ± sd s | on / off | on / off per seed: mean [95 % interval] "
             "| simulated s per wall s (min) | p95 on / off s (mean over seeds) "
             "| saved per seed s (off - on) | recovery events on / off (per seed) | stuck_feedback events on / off "
             "| robots that crossed a blocked corridor's mouth on / off (per seed) | reached on / off "
             "| broker bytes per robot per simulated minute, on: mean ± sd "
             "| obstacles shared (robots, walls) per seed "
             "| precision of shared cells against ground truth, min over seeds | face recall, min over seeds and blocks |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for n in sorted({r[0] for r in rows}):
        p = pooled(rows, n)
        if p is None:
            lines.append("| %d | none complete | | | | | | | | | | | | | | | |" % n)
            continue
        got, seeds, per_seed = p["got"], p["seeds"], p["per_seed"]
        p95 = [mean_sd([got[(s, sh)]["time_p95"] for s in seeds])[0] for sh in (True, False)]
        saved = ", ".join("%.1f" % (got[(s, False)]["time_mean"] - got[(s, True)]["time_mean"]) for s in seeds)
        reached = ["%d/%d" % (p["reached"][sh], n * len(seeds)) for sh in (True, False)]
        lines.append("| %d | %s | %s | %s | %.2f | %s | %s | %.1f / %.1f | %s | %s / %s | %s / %s | %s / %s | %s / %s | %s | %s | %s | %s |" % (
            n, " ".join(map(str, seeds)), fmt_mean_sd(p["on"]), fmt_mean_sd(p["off"]), p["ratio"],
            interval_text(p["per_seed_ratio"]),
            "%.2f" % p["factor"] if p["factor"] is not None else "-", p95[0], p95[1], saved,
            per_seed("recoveries", True), per_seed("recoveries", False),
            per_seed("stuck", True), per_seed("stuck", False),
            per_seed("entered_blocked_corridor", True), per_seed("entered_blocked_corridor", False),
            reached[0], reached[1],
            fmt_mean_sd([got[(s, True)].get("broker_bytes_per_robot_per_min", float("nan")) for s in seeds], 0),
            ", ".join("%s (%s, %s)" % (got[(s, True)].get("obstacles", "?"), got[(s, True)].get("obstacles_robots", "?"),
                                       got[(s, True)].get("obstacles_walls", "?")) for s in seeds),
            "%.3f" % p["precision"] if p["precision"] is not None else "-",
            "%.3f" % p["recall"] if p["recall"] is not None else "-"))
    return lines


def overview(by_layout):
    """One row per world and N ({layout: rows}, in the order given): what the per-world summaries say, side by side.
    A ratio that cannot be formed says why."""
    lines = ["| world | N | seeds | simulated s per wall s (min) | reached on / off | time to goal on / off: mean ± sd s "
             "| on / off | on / off per seed: mean [95 % interval] | recovery events on / off "
             "| robots that crossed a blocked corridor's mouth on / off | precision (min) | face recall (min) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for layout, rows in by_layout.items():
        for n in sorted({r[0] for r in rows}):
            p = pooled(rows, n)
            if p is None:
                lines.append("| %s | %d | none complete | | | | | | | | | |" % (layout, n))
                continue
            runs = n * len(p["seeds"])
            if not p["off"]:
                ratio, interval = "-", "- (no robot arrived without sharing)"
            elif not p["on"]:
                ratio, interval = "-", "- (no robot arrived with sharing)"
            else:
                ratio, interval = "%.2f" % p["ratio"], interval_text(p["per_seed_ratio"])
            lines.append("| %s | %d | %s | %s | %d/%d / %d/%d | %s / %s | %s | %s | %d / %d | %d / %d | %s | %s |" % (
                layout, n, " ".join(map(str, p["seeds"])), "%.2f" % p["factor"] if p["factor"] is not None else "-",
                p["reached"][True], runs, p["reached"][False], runs, fmt_mean_sd(p["on"]), fmt_mean_sd(p["off"]),
                ratio, interval, p["recoveries"][True], p["recoveries"][False], p["crossed"][True],
                p["crossed"][False], "%.3f" % p["precision"] if p["precision"] is not None else "-",
                "%.3f" % p["recall"] if p["recall"] is not None else "-"))
    return lines


def chart(rows, path, title):
    """A picture of the summary: per N, time to goal with sharing on and off (bar: mean over every robot
    of every complete seed, whisker: ± sd, dots: each seed's mean), and on / off above each pair.
    Returns {(n, sharing): (x0, top, x1, bottom)} of the bars drawn. Raises ValueError when no N has a
    seed with both runs."""
    from PIL import Image, ImageDraw
    groups = []
    for n in sorted({r[0] for r in rows}):
        p = pooled(rows, n)
        if p is None:
            continue
        got, seeds = p["got"], p["seeds"]
        bars, reached = {}, {}
        for sharing, times in ((True, p["on"]), (False, p["off"])):
            bars[sharing] = (mean_sd(times), [got[(s, sharing)]["time_mean"] for s in seeds])
            reached[sharing] = (sum(got[(s, sharing)].get("reached", len(got[(s, sharing)]["time_to_goal"]))
                                    for s in seeds), n * len(seeds))
        groups.append((n, seeds, bars, reached, p["factor"]))
    if not groups:
        raise ValueError("chart: no N with a seed that has both a sharing-on and a sharing-off result")
    top_value = max(m + sd for _n, _s, bars, _r, _f in groups for (m, sd), per_seed in bars.values()
                    for m, sd in [(m, sd if math.isfinite(sd) else 0.0)] if math.isfinite(m))
    top_value = max(top_value, max(v for _n, _s, bars, _r, _f in groups for _m, per_seed in bars.values()
                                   for v in per_seed if math.isfinite(v)))
    # wide enough for the subtitle whatever the number of groups
    width, height, left, bottom, top = max(660, 140 + 190 * len(groups)), 450, 70, 360, 60
    scale = (bottom - top) / (top_value * 1.1)
    img = Image.new("RGB", (width, height), "white")
    d = ImageDraw.Draw(img)
    d.text((10, 10), title, fill="black")
    d.text((10, 28), "time to goal (simulated s) of the robots that reached it: bar mean, whisker sd; dots: each "
           "seed's mean", fill=(90, 90, 90))
    step = 10 if top_value < 120 else 20
    for v in range(0, int(top_value * 1.1) + 1, step):
        y = bottom - v * scale
        d.line((left, y, width - 20, y), fill=(232, 232, 232))
        d.text((left - 30, y - 6), "%d" % v, fill="black")
    colours = {True: (40, 120, 200), False: (200, 110, 40)}
    drawn = {}
    for k, (n, seeds, bars, reached, factor) in enumerate(groups):
        x = left + 30 + k * 190
        for j, sharing in enumerate((True, False)):
            (m, sd), per_seed = bars[sharing]
            x0, x1 = x + j * 70, x + j * 70 + 56
            if not math.isfinite(m):
                # no bar: say so where it would stand
                d.text((x0 + 2, bottom - 30), "none", fill="black")
                d.text((x0 + 2, bottom - 16), "arrived", fill="black")
                d.text((x0 + 8, bottom + 6), "on" if sharing else "off", fill="black")
                d.text((x0, bottom + 40), "%d/%d" % reached[sharing], fill="black")
                continue
            y = bottom - m * scale
            d.rectangle((x0, y, x1, bottom), fill=colours[sharing])
            drawn[(n, sharing)] = (x0, y, x1, bottom)
            cx = (x0 + x1) / 2
            d.line((cx, bottom - (m + sd) * scale, cx, bottom - max(0.0, m - sd) * scale), fill="black", width=2)
            for i, v in enumerate(per_seed):
                if math.isfinite(v):
                    px, py = x0 + 10 + i * 12, bottom - v * scale
                    d.ellipse((px - 3, py - 3, px + 3, py + 3), fill="white", outline="black")
            d.text((x0 + 8, bottom + 6), "on" if sharing else "off", fill="black")
            d.text((x0, bottom + 40), "%d/%d" % reached[sharing], fill="black")
        (m_on, _), _ = bars[True]
        (m_off, _), _ = bars[False]
        ratio = "on/off %.2f" % (m_on / m_off) if m_off and math.isfinite(m_on) and math.isfinite(m_off) else \
            "on/off -"   # the bar slot that has none says why
        speed = "" if factor is None or factor >= 0.995 else ", Stage x%.2f" % factor
        d.text((x, bottom + 24), "N = %d (seeds %s)%s" % (n, " ".join(map(str, seeds)), speed), fill="black")
        d.text((x, bottom + 56), "robots that reached their goal", fill=(90, 90, 90))
        d.text((x, top - 16), ratio, fill="black")
    img.save(path)
    return drawn


HEADER = ("| N | seed | sharing | simulated s per wall s | dispatch order | recovery events (move_base/recovery_status) | stuck_feedback events "
          "| robots that crossed a blocked corridor's mouth | reached | time to goal mean / p95 s | distance m "
          "| broker bytes per robot per simulated minute ($SYS: fan-out and MQTT overhead included) "
          "| payload bytes published by the bridges | latency p50 / p99 ms (n: obstacle x peer pairs; a pair that "
          "never arrived counts as lost, inf) "
          "| obstacles shared, distinct after merging (robots, walls) |")


def latency_cell(r):
    """p50 / p99 with the sample count; below 30 samples, why (a p99 of fewer is no more than their maximum).
    ``latency_missed`` (pairs that never arrived, counted as lost in the percentiles) is absent in older runs."""
    missed = r.get("latency_missed")
    n = len(r.get("latency_ms", [])) + (missed or 0)
    lost = ", %d lost" % missed if missed else ("" if missed is not None else ", lost not counted (older run)")
    if n >= 30:
        count = "n = %d%s" % (n, lost)
    else:
        count = "n = %d < 30: only %d obstacle x peer pairs in this run (few robots and shares)%s" % (n, n, lost)
    return "%.1f / %.1f (%s)" % (r["latency_ms_p50"], r["latency_ms_p99"], count)


def run_table(rows):
    """The Markdown table of every run: one row per layout's (N, sharing, seed, result or None)."""
    # Headers say what is measured: recovery_status messages and stuck_feedback messages, robots
    # whose true track crossed the start-side end of a corridor with a block, bytes from the
    # broker's $SYS counters (sent + received, per robot per minute of simulated time), the
    # bridges' payload bytes, obstacles after merging with those that lay on a robot or a wall.
    table = [HEADER, "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for n, sharing, seed, r in rows:
        if r is None:
            table.append("| %d | %d | %s | no result | | | | | | | | | | | |" % (n, seed, "on" if sharing else "off"))
            continue
        lat = latency_cell(r) if sharing else "-"
        order = " ".join(d["robot"][len("robot_"):] for d in r.get("dispatch", []))
        per_min = r.get("broker_bytes_per_robot_per_min")   # None: a run from before the $SYS count
        factor = r.get("realtime_factor")
        table.append("| %d | %d | %s | %s | %s | %s | %d | %d | %d/%d | %.1f / %.1f | %.1f | %s | %d | %s | %s |" % (
            n, seed, "on" if sharing else "off", "%.2f" % factor if isinstance(factor, (int, float)) else "?",
            order or "?", r.get("recoveries", "?"), r["stuck"],
            r["entered_blocked_corridor"], r["reached"], n, r["time_mean"], r["time_p95"], r["distance_m"],
            ("%.0f" % per_min if per_min is not None else "?") if sharing else "-", r.get("payload_bytes_bridges", r.get("bytes_on_bus", 0)), lat,
            "%s (%s, %s)" % (r.get("obstacles", "?"), r.get("obstacles_robots", "?"), r.get("obstacles_walls", "?"))
            if sharing else "-"))
    return table
