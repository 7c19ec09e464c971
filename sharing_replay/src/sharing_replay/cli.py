"""Command line of the offline bag replay: ``rosrun sharing_replay replay BAG [options]``.

Exit codes (also in README.md): 0 everything replayed; 2 bad command line, parameters or map;
3 the bag cannot be opened; 4 no LaserScan topic to replay; 1 an internal error (a bug).
A replay that ran but met bad input exits with the sum of: 8 bag damaged (truncated,
unreadable chunks, undeserialisable messages), 16 scans dropped for tf (gap, extrapolation,
frame not connected), 32 a trigger/tf topic missing or messages with bad content.
"""
import argparse
import json
import logging
import os
import sys
import time
import traceback

from sharing_replay import report
from sharing_replay.errors import BagOpenError, InputError, MissingTopicError

LOG = logging.getLogger("sharing_replay")


def _trigger_at(text):
    out = []
    for item in text.split(","):
        item = item.strip()
        if not item:
            continue
        robot, _, value = item.rpartition("@")
        try:
            t = float(value)
        except ValueError:
            raise argparse.ArgumentTypeError("--trigger-at: %r is not [robot@]seconds" % item) from None
        out.append((robot or None, t))
    return out


def build_parser():
    p = argparse.ArgumentParser(
        prog="replay", description="Replays the obstacle-sharing layer and handler over a ROS 1 bag, offline "
        "(no roscore): JSON Lines of every proposal, authorisation, update and expiry, a summary and a PNG.")
    p.add_argument("bag", help="the .bag file")
    g = p.add_argument_group("map (default: the bag's /map topic)")
    g.add_argument("--map", dest="map_yaml", help="map_server YAML (image, resolution, origin, thresholds)")
    g.add_argument("--map-image", help="map image, with --resolution (map_server's <image> <resolution>)")
    g.add_argument("--resolution", type=float, help="metres per pixel of --map-image")
    g.add_argument("--origin", type=float, nargs=2, default=(0.0, 0.0), metavar=("X", "Y"),
                   help="lower-left corner of --map-image in the map frame (default 0 0)")
    g.add_argument("--allow-map-mismatch", action="store_true",
                   help="replay on the given map even where it is not the bag's /map (resolution, origin, size)")
    g = p.add_argument_group("topics and frames")
    g.add_argument("--scan-topic", default="base_scan",
                   help="LaserScan topic: relative (default base_scan: every <ns>/base_scan is a robot) or absolute")
    g.add_argument("--robots", default="", help="comma-separated namespaces to replay (default: all found)")
    g.add_argument("--robot-name", default="robot", help="name of the robot of an un-namespaced bag (default robot)")
    g.add_argument("--global-frame", default="map")
    g.add_argument("--base-frame", default="base_link",
                   help="robot frame for proposals; prefixed with the namespace (default base_link)")
    g.add_argument("--trigger", default="auto", choices=("auto", "stuck_feedback", "recovery_status", "both", "none"),
                   help="trigger topics: <ns>/stuck_feedback, <ns>/move_base/recovery_status (auto: those present)")
    g.add_argument("--plan-topics", default="move_base/NavfnROS/plan,move_base/GlobalPlanner/plan",
                   help="comma-separated nav_msgs/Path topics (relative to each namespace) for the layer's "
                        "plan-blocked trigger; 'none' switches it off (default: move_base's navfn and global_planner)")
    g.add_argument("--no-robot-exclusion", action="store_true",
                   help="for comparison only: share the bag's other robots too, as a layer without the fleet's "
                        "robot exclusion would (default: they are placed from tf and never shared)")
    g.add_argument("--trigger-at", type=_trigger_at, default=[], action="append",
                   help="extra triggers, seconds from the bag start: '19.5,robot_1@40' (repeatable)")
    g = p.add_argument_group("layer and handler parameters")
    g.add_argument("--params", action="append", default=[], metavar="YAML",
                   help="move_base/costmap parameter file, as loaded into fleet_nav (repeatable, merged in order)")
    g.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                   help="one parameter, e.g. obstacle_range=3.0 or sharing/static_tolerance=3 (repeatable)")
    g.add_argument("--obstacle-range", type=float)
    g.add_argument("--raytrace-range", type=float)
    g.add_argument("--static-tolerance", type=int)
    g.add_argument("--trigger-debounce", type=float)
    g.add_argument("--proposal-strategy")
    g.add_argument("--obstacle-duration", type=float, default=1200.0, help="handler deadline, s (default 1200, the handler's)")
    g.add_argument("--expiry-rate", type=float, default=1.0, help="handler expiry checks per second (default 1)")
    g.add_argument("--max-cells-per-message", type=int, default=100000)
    g = p.add_argument_group("tf")
    g.add_argument("--tf-max-gap", type=float, default=1.0, help="longest interpolated gap in an edge, s (default 1)")
    g.add_argument("--tf-tolerance", type=float, default=0.2,
                   help="nearest sample accepted this far outside an edge's samples, s (default 0.2)")
    g.add_argument("--tf-wait", type=float, default=1.0,
                   help="bag seconds a scan waits for its transform (default 1)")
    g = p.add_argument_group("output")
    g.add_argument("--out-dir", default="replay_out", help="folder for events.jsonl, summary.json, map.png")
    g.add_argument("--events", help="JSON Lines file (default <out-dir>/events.jsonl)")
    g.add_argument("--summary", help="summary JSON (default <out-dir>/summary.json)")
    g.add_argument("--png", help="picture (default <out-dir>/map.png)")
    g.add_argument("--no-png", action="store_true")
    g.add_argument("--png-scale", type=int, help="pixels per map cell (default: about 1000 px wide)")
    g.add_argument("--wall-distance", type=int, default=3,
                   help="a shared cell within this many cells of a static wall counts as near a wall (default 3)")
    g.add_argument("--seed", type=int, default=0, help="seed of the obstacle uuids (default 0)")
    g.add_argument("--progress", choices=("auto", "always", "never"), default="auto",
                   help="progress bar on stderr (auto: when stderr is a terminal, else a line every 5 s)")
    g.add_argument("-q", "--quiet", action="store_true", help="no progress, only warnings and the summary")
    g.add_argument("-v", "--verbose", action="store_true", help="log every handler decision")
    return p


class Progress:
    def __init__(self, mode, stream=sys.stderr):
        self.stream = stream
        self.bar = mode == "always" or (mode == "auto" and stream.isatty())
        self.enabled = mode != "never"
        self.last_line = 0.0

    def __call__(self, replay, wall, final=False):
        if not self.enabled:
            return
        total = max(replay.total_messages, replay.messages, 1)
        frac = replay.messages / total
        rate = replay.messages / wall if wall > 0 else 0.0
        scan_rate = replay.scans / wall if wall > 0 else 0.0
        bag_t = replay.now - replay.start_time
        text = "%5.1f%% %d/%d msgs  %.0f msg/s  %.0f scans/s  bag t=%.1f s  %d shared" % (
            100.0 * frac, replay.messages, total, rate, scan_rate, bag_t, len(replay.obstacles))
        if self.bar:
            width = 30
            filled = int(round(width * frac))
            self.stream.write("\r[%s%s] %s" % ("#" * filled, "." * (width - filled), text))
            if final:
                self.stream.write("\n")
        else:
            now = time.monotonic()
            if not final and now - self.last_line < 5.0:
                return
            self.last_line = now
            self.stream.write("replay: %s\n" % text)
        self.stream.flush()


def settings_from_args(args):
    from sharing_replay.config import ReplaySettings, exclusion_from_tree, layer_kwargs_from_tree, load_params_tree
    tree = load_params_tree(args.params, args.param)
    layer, lethal, unknown, _unused = layer_kwargs_from_tree(tree)
    exclusion = exclusion_from_tree(tree)
    for key in ("obstacle_range", "raytrace_range", "static_tolerance", "trigger_debounce", "proposal_strategy"):
        value = getattr(args, key)
        if value is not None:
            layer[key] = value
    trigger_at = tuple(item for group in args.trigger_at for item in group)
    robots = tuple(r.strip().strip("/") for r in args.robots.split(",") if r.strip())
    plan_topics = () if args.plan_topics.strip() in ("", "none") else tuple(
        t.strip().strip("/") for t in args.plan_topics.split(",") if t.strip())
    return ReplaySettings(
        scan_topic=args.scan_topic, global_frame=args.global_frame.strip("/"), base_frame=args.base_frame.strip("/"),
        robots=robots, single_robot_name=args.robot_name, trigger=args.trigger, trigger_at=trigger_at,
        plan_topics=plan_topics,
        tf_max_gap=args.tf_max_gap, tf_tolerance=args.tf_tolerance, tf_wait=args.tf_wait,
        obstacle_duration=args.obstacle_duration, expiry_rate=args.expiry_rate,
        max_cells_per_message=args.max_cells_per_message, wall_distance=args.wall_distance, layer=layer,
        lethal_cost_threshold=lethal, track_unknown_space=unknown, seed=args.seed,
        robot_exclusion=not args.no_robot_exclusion, allow_map_mismatch=args.allow_map_mismatch, **exclusion)


def run(argv=None, stdout=sys.stdout, stderr=sys.stderr):
    """Runs one replay; returns (exit code, summary dict or None)."""
    args = build_parser().parse_args(argv)
    from sharing_replay.bag_reader import BagSource
    from sharing_replay.config import load_map
    from sharing_replay.runner import Replay
    try:
        settings = settings_from_args(args)
        map_data = None
        if args.map_yaml or args.map_image:
            if args.map_yaml and args.map_image:
                raise InputError("give --map or --map-image, not both")
            map_data = load_map(args.map_yaml, args.map_image, args.resolution, tuple(args.origin) + (0.0,))
        if args.png_scale is not None and not 1 <= args.png_scale <= 50:
            raise InputError("--png-scale must be 1..50, got %d" % args.png_scale)
    except InputError as err:
        stderr.write("replay: %s\n" % err)
        return report.EXIT_USAGE, None
    try:
        source = BagSource(args.bag)
    except BagOpenError as err:
        stderr.write("replay: %s\n" % err)
        return report.EXIT_BAG_UNREADABLE, None
    events_path = args.events or os.path.join(args.out_dir, "events.jsonl")
    summary_path = args.summary or os.path.join(args.out_dir, "summary.json")
    png_path = None if args.no_png else (args.png or os.path.join(args.out_dir, "map.png"))
    try:
        for path in (events_path, summary_path, png_path):
            if path and os.path.dirname(path):
                os.makedirs(os.path.dirname(path), exist_ok=True)
        with open(events_path, "w", encoding="utf-8") as events:
            def write_event(record):
                events.write(json.dumps(record, separators=(",", ":")) + "\n")
            progress = Progress("never" if args.quiet else args.progress, stderr)
            replay = Replay(settings, map_data, on_event=write_event, on_progress=progress)
            try:
                replay.run(source)
            except MissingTopicError as err:
                stderr.write("replay: %s\n" % err)
                for note in source.notes:
                    stderr.write("replay: (the bag is damaged: %s)\n" % note)
                return report.EXIT_NO_SCANS, None
            except InputError as err:
                stderr.write("replay: %s\n" % err)
                return report.EXIT_USAGE, None
        summary = report.summarise(replay, os.path.abspath(args.bag))
        if png_path:
            report.render_png(replay, png_path, args.png_scale)
            summary["png"] = os.path.abspath(png_path)
        summary["events"] = os.path.abspath(events_path)
        with open(summary_path, "w", encoding="utf-8") as handle:
            json.dump(summary, handle, indent=1)
        stdout.write(report.summary_text(summary) + "\n")
        stdout.write("wrote %s, %s%s\n" % (events_path, summary_path, ", " + png_path if png_path else ""))
        return summary["exit_code"], summary
    except OSError as err:
        stderr.write("replay: cannot write the output: %s\n" % err)
        return report.EXIT_USAGE, None
    finally:
        source.close()


def configure_logging(argv):
    """Warnings (or, with -v, every decision) on stderr. Only the command line does this: run()
    leaves the process's logging alone, so tests and other callers keep theirs."""
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, stream=sys.stderr,
                        format="replay: %(levelname)s: %(message)s")
    if not args.verbose:
        # The handler logs one line per drop; the replay counts them in the summary instead.
        logging.getLogger("sharing_handler_py").setLevel(logging.ERROR)


def main(argv=None):
    try:
        configure_logging(argv)
        code, _summary = run(argv)
    except KeyboardInterrupt:
        sys.stderr.write("replay: interrupted\n")
        code = 130
    except Exception:  # noqa: BLE001 - the last resort: say it is a bug, with the traceback
        traceback.print_exc()
        sys.stderr.write("replay: internal error (a bug in the replay, please report it with the traceback)\n")
        code = report.EXIT_INTERNAL
    sys.exit(code)
