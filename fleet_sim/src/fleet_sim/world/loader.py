"""Stage world loader: a ``.world`` file → a validated ``World``.

What is read (everything else is ignored with a debug line):

- top level: ``resolution`` (raytrace grid, m), ``interval_sim`` (ms), ``speedup``;
- ``model`` with ``bitmap`` (PNG, PGM or anything Pillow reads; path relative to
  the file that names it, else to the world file's folder): a floorplan. Stage's
  rule: a pixel darker than mid-grey (< 128) is an obstacle; the image is stretched
  to ``size`` and centred on ``pose``; ``boundary 1`` adds a wall around its edge;
- ``model`` without bitmap: a solid block of ``size`` at ``pose``. Models with
  ``obstacle_return 0`` are not collided with, with ``ranger_return`` < 0 they are
  invisible to lasers;
- ``position``: a robot (``pose``, ``size``, ``origin``, ``color``, ``name``,
  ``drive`` "diff" | "omni"); robots are numbered in file order (robot_0 first). A ``position``
  without a ranger is a movable block (``obstacle_return``, ``ranger_return`` as for ``model``): in
  Stage a test drives it by cmd_vel, here the block services move it;
- ``ranger`` inside a robot, with a ``sensor( range [min max] | range_min/range_max,
  fov, samples, pose )``, the Stage-3 ``laser`` model (``range_min``, ``range_max``,
  ``fov``, ``samples`` on the model) or a ranger carrying those properties itself.
  Like stage_ros, only the first sensor of a ranger becomes a scan.

Range decision (DESIGN.md §7, issue 28): Stage 4.3 reads only ``sensor( range [min max] ...)``
and silently ignores the Stage-3 spellings (``range_min``/``range_max``, ``view``, properties on
the ranger itself; the ``laser`` model it refuses), falling back to its default 0-5 m. We WARN on
each, naming file:line, robot and value, and read it as written (the Willow world's
``range_max 30.0`` is the 30 m scanner of the original tests); where ``range`` is given it wins, as
in Stage. ``stage43_range_compat=True`` reads exactly as Stage 4.3: the Stage-3 spellings are
ignored (with the warning) and the default [0, 5] applies, as in the recorded stageros bags.

Errors: a file that cannot be parsed raises ``WorldSyntaxError`` (file, line,
reason). A model with a bad value (bad pose, negative size, zero samples, ...) is
dropped with one error line naming file, line and value, recorded in
``World.problems``; the rest of the world loads. ``strict=True`` raises
``WorldError`` for those instead. A floorplan bitmap that is missing or unreadable
always raises ``WorldError``: without it the world has no walls, and a simulation
of it would only look like it runs.
"""
import logging
import math
import os

import numpy as np

from fleet_sim import frames
from fleet_sim.errors import WorldError
from fleet_sim.world.model import BlockSpec, FloorplanSpec, RangerSpec, RobotSpec, World
from fleet_sim.world.parser import parse_world

_LOG = logging.getLogger(__name__)

STAGE_DEFAULT_RANGE = (0.0, 5.0)      # Stage 4 ModelRanger::Sensor default
STAGE_DEFAULT_FOV_DEG = 0.1 * 180.0 / math.pi
STAGE3_LASER_DEFAULTS = dict(range_min=0.0, range_max=8.0, fov=180.0, samples=180)

# Properties each type uses; anything else gets a debug line.
_USED = {
    "model": {"pose", "size", "color", "color_rgba", "name", "bitmap", "boundary",
              "obstacle_return", "ranger_return"},
    "position": {"pose", "size", "origin", "color", "color_rgba", "name", "drive"},
    "ranger": {"pose", "size", "color", "color_rgba", "name", "range", "range_min",
               "range_max", "fov", "samples"},
    "laser": {"pose", "size", "color", "color_rgba", "name", "range_min", "range_max",
              "fov", "samples"},
    "sensor": {"pose", "size", "range", "range_min", "range_max", "fov", "samples",
               "view", "color_rgba"},
}
_WORLD_USED = {"resolution", "interval_sim", "speedup"}


class _Drop(Exception):
    """A model with a bad value: dropped (or raised in strict mode); a fatal one is always raised."""

    def __init__(self, prop_or_entity, reason, fatal=False):
        super().__init__(reason)
        self.path = prop_or_entity.path
        self.line = prop_or_entity.line
        self.reason = reason
        self.fatal = fatal


def load_world(path, stage43_range_compat=False, strict=False, log=None):
    """Loads a Stage world file; see the module docstring for what is read.

    ``log(level, message)`` with level in {'debug', 'info', 'warn', 'error'}
    receives every line; by default they go to this module's logger.
    """
    log = log or _default_log
    parsed = parse_world(path, log)
    world = World(path=parsed.path, files=list(parsed.files))

    for name, prop in parsed.props.items():
        if name not in _WORLD_USED:
            log("debug", "%s: world property '%s' ignored" % (prop.where(), name))
    try:
        if "resolution" in parsed.props:
            world.resolution = _positive(parsed.props["resolution"], "resolution")
        if "interval_sim" in parsed.props:
            world.interval_sim = _positive(parsed.props["interval_sim"], "interval_sim") / 1000.0
        if "speedup" in parsed.props:
            world.speedup = _number(parsed.props["speedup"])
            if world.speedup < 0 and world.speedup != -1:
                raise _Drop(parsed.props["speedup"], "speedup must be >= 0 (or -1), got %g" % world.speedup)
            world.speedup = max(world.speedup, 0.0)
    except _Drop as drop:
        raise WorldError(drop.path, drop.line, drop.reason) from None

    counters = {}
    ctx = _Ctx(world, log, stage43_range_compat, counters)
    for ent in parsed.entities:
        if ent.type == "window":
            log("debug", "%s: GUI 'window' ignored (headless)" % ent.where())
            continue
        ctx.load_entity(ent, (0.0, 0.0, 0.0), strict)
    return world


def require_robots(world, count):
    """Raises WorldError unless the world holds at least `count` robots (a launch that drives robot_0 ..
    robot_{count-1}: without this, the missing robots' navigation waits for a pose for ever)."""
    if len(world.robots) < count:
        raise WorldError(world.path, 0, "holds %d robot(s) (%s), but %d are to be driven (robots:=%d): give a world "
                         "with at least %d robots (fleet_launch's worlds/<layout>_%d.world) or fewer robots"
                         % (len(world.robots), ", ".join(r.name for r in world.robots) or "none", count, count,
                            count, count))


def _default_log(level, msg):
    _LOG.log({"debug": logging.DEBUG, "info": logging.INFO, "warn": logging.WARNING,
              "error": logging.ERROR}[level], msg)


class _Ctx:
    def __init__(self, world, log, compat, counters):
        self.world = world
        self.log = log
        self.compat = compat
        self.counters = counters

    def auto_name(self, ent):
        """Stage-style name for an unnamed model: '<kind>:<n>' per kind, e.g. 'block:0'."""
        n = self.counters.get(ent.kind, 0)
        self.counters[ent.kind] = n + 1
        return "%s:%d" % (ent.kind, n)

    def debug_unused(self, ent, used):
        for name, prop in ent.props.items():
            if name not in used:
                self.log("debug", "%s: property '%s' of %s '%s' ignored"
                         % (prop.where(), name, ent.type, ent.kind))

    def load_entity(self, ent, parent_pose, strict):
        try:
            if ent.type == "model":
                self.load_model(ent, parent_pose, strict)
            elif ent.type == "position" and not any(c.type in ("ranger", "laser") for c in ent.children):
                self.load_movable(ent, parent_pose)
            elif ent.type == "position":
                self.load_robot(ent, parent_pose)
            elif ent.type in ("ranger", "laser", "sensor"):
                self.log("warn", "%s: %s '%s' outside a robot ignored (nothing publishes it)"
                         % (ent.where(), ent.type, ent.kind))
            elif ent.type == "block":
                self.log("debug", "%s: block geometry outside a model ignored" % ent.where())
            else:
                self.log("debug", "%s: model type '%s' not simulated, ignored" % (ent.where(), ent.type))
        except _Drop as drop:
            if strict or drop.fatal:
                raise WorldError(drop.path, drop.line, drop.reason) from None
            msg = "%s:%d: %s; %s %s dropped" % (drop.path, drop.line, drop.reason, ent.type, _label(ent))
            self.world.problems.append(msg)
            self.log("error", msg)

    # --- models -------------------------------------------------------------
    def load_model(self, ent, parent_pose, strict):
        self.debug_unused(ent, _USED["model"])
        name = _string(ent, "name", None) or self.auto_name(ent)
        pose = frames.compose(parent_pose, _pose(ent))
        size = _size(ent)
        color = _color(ent, (128, 128, 128), self.log)
        obstacle = _number_prop(ent, "obstacle_return", 1.0) != 0
        visible = _number_prop(ent, "ranger_return", 1.0) >= 0
        if "bitmap" in ent.props:
            prop = ent.props["bitmap"]
            if not isinstance(prop.value, str) or not prop.value:
                raise _Drop(prop, "bitmap must be a quoted file name, got %r" % (prop.value,), fatal=True)
            bitmap = os.path.normpath(os.path.join(os.path.dirname(prop.path), prop.value))
            if not os.path.isfile(bitmap):   # Stage resolves against the world file's folder
                beside_world = os.path.normpath(os.path.join(os.path.dirname(self.world.path), prop.value))
                if os.path.isfile(beside_world):
                    bitmap = beside_world
            occupied = _read_bitmap(bitmap, prop)
            self.world.floorplans.append(FloorplanSpec(
                name=name, pose=pose, size=size, bitmap_path=bitmap, occupied=occupied,
                boundary=_number_prop(ent, "boundary", 0.0) != 0, color=color,
                obstacle=obstacle, visible=visible, where=ent.where()))
        else:
            self.world.blocks.append(BlockSpec(name=name, pose=pose, size=size, color=color,
                                               obstacle=obstacle, visible=visible, where=ent.where()))
        for child in ent.children:
            if child.type == "block":
                continue  # polygon geometry of this model; we use its size rectangle
            self.load_entity(child, pose, strict)

    def load_movable(self, ent, parent_pose):
        """A position model without a ranger: an object a test moves while the simulation runs (the worlds'
        blocks: stageros drives them by cmd_vel, fleet_sim by its block services). A block, not a robot:
        it gets no robot_N number, no scan and no odometry."""
        self.debug_unused(ent, _USED["position"] | {"obstacle_return", "ranger_return"})
        name = _string(ent, "name", None) or self.auto_name(ent)
        self.world.blocks.append(BlockSpec(
            name=name, pose=frames.compose(parent_pose, _pose(ent)), size=_size(ent),
            color=_color(ent, (128, 128, 128), self.log),
            obstacle=_number_prop(ent, "obstacle_return", 1.0) != 0,
            visible=_number_prop(ent, "ranger_return", 1.0) >= 0, where=ent.where()))

    def load_robot(self, ent, parent_pose):
        self.debug_unused(ent, _USED["position"])
        index = len(self.world.robots)
        name = _string(ent, "name", None) or self.auto_name(ent)
        pose = frames.compose(parent_pose, _pose(ent))
        size = _size(ent)
        origin = _tuple(ent, "origin", (0.0, 0.0, 0.0, 0.0), (3, 4))
        drive = _string(ent, "drive", "diff")
        if drive not in ("diff", "omni"):
            raise _Drop(ent.props["drive"], "drive must be \"diff\" or \"omni\", got %r" % drive)
        rangers = []
        for child in ent.children:
            if child.type in ("ranger", "laser"):
                try:
                    spec = self.load_ranger(child, "robot_%d/%s" % (index, child.kind), name)
                except _Drop as drop:
                    msg = "%s:%d: %s; ranger '%s' of robot %s dropped (robot kept)" % (
                        drop.path, drop.line, drop.reason, child.kind, name)
                    self.world.problems.append(msg)
                    self.log("error", msg)
                    continue
                if spec is not None:
                    rangers.append(spec)
            elif child.type != "block":
                self.log("debug", "%s: %s '%s' inside robot %s not simulated, ignored"
                         % (child.where(), child.type, child.kind, name))
        self.world.robots.append(RobotSpec(
            name=name, pose=pose, size=size, origin=(origin[0], origin[1]),
            color=_color(ent, (255, 0, 0), self.log), drive=drive, rangers=tuple(rangers),
            where=ent.where(), height=_height(ent)))

    def load_ranger(self, ent, label, robot="?"):
        """One ranger of a robot. Stage 4.3 reads a ranger only from its sensor( range [min max] fov
        samples ): the Stage-3 spellings (a 'laser' model, range_min / range_max / view, properties
        on the ranger itself) are what it silently ignores, so each gets a WARN naming the robot, the
        value and what Stage 4.3 does instead. They are read as written (the world author's intent,
        e.g. the tutorials' Willow 30 m), or, with ``stage43_range_compat``, ignored as Stage 4.3 does."""
        self.debug_unused(ent, _USED[ent.type])
        pose = _pose(ent)
        z = _pose_z(ent)
        sensors = [c for c in ent.children if c.type == "sensor"]
        who = "robot %s (%s), %s '%s'" % (robot, label.split("/")[0], ent.type, ent.kind)
        if ent.type == "laser":
            if self.compat:
                raise _Drop(ent, "%s: Stage 4.3 has no 'laser' model (it stops: \"Unknown model type laser\"); "
                                 "write ranger( sensor( range [min max] fov samples ) )" % who)
            self.log("warn", "%s: %s: Stage-3 'laser' model read as written; Stage 4.3 has no 'laser' model "
                     "and refuses this world; write ranger( sensor( range [min max] fov samples ) )"
                     % (ent.where(), who))
            src = ent
            defaults = STAGE3_LASER_DEFAULTS
        elif sensors:
            src = sensors[0]
            if len(sensors) > 1:
                self.log("warn", "%s: ranger '%s' has %d sensors; like stage_ros only the first "
                         "is published" % (ent.where(), ent.kind, len(sensors)))
            self.debug_unused(src, _USED["sensor"])
            pose = frames.compose(pose, _pose(src))
            z += _pose_z(src)
            defaults = dict(range_min=STAGE_DEFAULT_RANGE[0], range_max=STAGE_DEFAULT_RANGE[1],
                            fov=STAGE_DEFAULT_FOV_DEG, samples=1)
        elif any(k in ent.props for k in ("range", "range_min", "range_max", "view", "samples", "fov")):
            if self.compat:
                self.log("warn", "%s: %s: range, fov and samples on the ranger itself ignored "
                         "(stage43_range_compat): Stage 4.3 reads them only inside sensor( ... ), so this "
                         "ranger has no sensor and no scan" % (ent.where(), who))
                return None
            self.log("warn", "%s: %s: range, fov and samples on the ranger itself read as written; Stage 4.3 "
                     "reads them only inside sensor( ... ) and would give this ranger no scan"
                     % (ent.where(), who))
            src = ent
            defaults = dict(range_min=STAGE_DEFAULT_RANGE[0], range_max=STAGE_DEFAULT_RANGE[1],
                            fov=STAGE_DEFAULT_FOV_DEG, samples=1)
        else:
            self.log("warn", "%s: ranger '%s' has no sensor; nothing to publish" % (ent.where(), ent.kind))
            return None
        rmin, rmax = defaults["range_min"], defaults["range_max"]
        fov_deg, samples = defaults["fov"], defaults["samples"]
        if "range" in src.props:
            r = _tuple(src, "range", None, (2,))
            rmin, rmax = r
        stage3 = [k for k in ("range_min", "range_max", "view") if k in src.props]
        if stage3 and ent.type != "laser":
            written = " ".join("%s %s" % (k, _shown(src.props[k].value)) for k in stage3)
            where = src.props[stage3[0]].where()
            if "range" in src.props:
                # Stage 4.3 reads range and ignores the rest; so do we, in both modes
                self.log("warn", "%s: %s: Stage-3 '%s' ignored: range [%g %g] is given, and Stage 4.3 reads "
                         "only that; remove it" % (where, who, written, rmin, rmax))
                stage3 = []
            elif self.compat:
                self.log("warn", "%s: %s: Stage-3 '%s' ignored (stage43_range_compat): range is [%g %g] as in "
                         "Stage 4.3, which reads only range [min max]" % (where, who, written, rmin, rmax))
                stage3 = []
        if stage3:
            if "view" in src.props:             # Stage-3 sonar: view [min max fov]
                rmin, rmax, fov_deg = _tuple(src, "view", None, (3,))
            if "range_min" in src.props:
                rmin = _number_prop(src, "range_min", rmin)
            if "range_max" in src.props:
                rmax = _number_prop(src, "range_max", rmax)
            if ent.type != "laser":
                self.log("warn", "%s: %s: Stage-3 '%s' read as written, range [%g %g]; Stage 4.3 ignores it "
                         "and uses [%g %g]; write range [ %g %g ]" % (
                             src.props[stage3[0]].where(), who, written, rmin, rmax,
                             STAGE_DEFAULT_RANGE[0], STAGE_DEFAULT_RANGE[1], rmin, rmax))
        fov_deg = _number_prop(src, "fov", fov_deg)
        if "samples" in src.props:
            prop = src.props["samples"]
            samples = _number(prop)
            if samples != int(samples) or samples < 1:
                raise _Drop(prop, "samples must be a whole number >= 1, got %g" % samples)
        if not (0.0 < fov_deg <= 360.0):
            raise _Drop(src.props.get("fov", src), "fov must be in (0, 360] degrees, got %g" % fov_deg)
        if not (0.0 <= rmin < rmax) or not math.isfinite(rmax):
            where = src.props.get("range_max") or src.props.get("range") or src
            raise _Drop(where, "range must satisfy 0 <= min < max, got [%g %g]" % (rmin, rmax))
        return RangerSpec(name=label, pose=pose, range_min=float(rmin), range_max=float(rmax),
                          fov=math.radians(fov_deg), samples=int(samples), where=ent.where(), z=z)


def _shown(value):
    """A property value as written in a world file: 30, [0 30 90], "x"."""
    if isinstance(value, tuple):
        return "[%s]" % " ".join(_shown(v) for v in value)
    return "%g" % value if isinstance(value, float) else repr(value)


def _label(ent):
    """'name' (kind) for log lines, e.g. "'pr2_0' (pr2)" or "(block)" when unnamed."""
    name = ent.props.get("name")
    if name is not None and isinstance(name.value, str):
        return "'%s' (%s)" % (name.value, ent.kind)
    return "(%s)" % ent.kind


# --- property readers: each raises _Drop naming the property ------------------

def _number(prop):
    if isinstance(prop.value, float) and math.isfinite(prop.value):
        return prop.value
    raise _Drop(prop, "'%s' must be a number, got %r" % (prop.name, prop.value))


def _positive(prop, what):
    v = _number(prop)
    if v <= 0:
        raise _Drop(prop, "'%s' must be > 0, got %g" % (what, v))
    return v


def _number_prop(ent, name, default):
    if name not in ent.props:
        return default
    return _number(ent.props[name])


def _string(ent, name, default):
    if name not in ent.props:
        return default
    prop = ent.props[name]
    if not isinstance(prop.value, str):
        raise _Drop(prop, "'%s' must be a quoted string, got %r" % (name, prop.value))
    return prop.value


def _tuple(ent, name, default, counts):
    if name not in ent.props:
        return default
    prop = ent.props[name]
    v = prop.value
    if not isinstance(v, tuple) or len(v) not in counts or \
            not all(isinstance(x, float) and math.isfinite(x) for x in v):
        raise _Drop(prop, "'%s' must be [%s numbers], got %r"
                    % (name, " or ".join(str(c) for c in counts), v))
    return v


def _pose(ent):
    """Stage pose [x y z yaw_deg] (Stage 4) or [x y yaw_deg] (Stage 3) → (x, y, yaw rad)."""
    v = _tuple(ent, "pose", (0.0, 0.0, 0.0, 0.0), (3, 4))
    yaw = v[3] if len(v) == 4 else v[2]
    return (v[0], v[1], frames.normalize_angle(math.radians(yaw)))


def _pose_z(ent):
    """The z of a Stage 4 pose [x y z yaw_deg] (0 for a Stage 3 pose [x y yaw_deg])."""
    v = _tuple(ent, "pose", (0.0, 0.0, 0.0, 0.0), (3, 4))
    return float(v[2]) if len(v) == 4 else 0.0


def _height(ent):
    """Stage size z of a model ([x y z]); 0 for a Stage 3 size [x y]. stage_ros puts a robot's lasers this
    high (plus their own pose z): costmap_2d's min_obstacle_height drops points below it."""
    v = _tuple(ent, "size", (0.4, 0.4, 1.0), (2, 3))
    return float(v[2]) if len(v) == 3 else 0.0


def _size(ent):
    """Stage size [x y z] or [x y]; both x and y must be > 0."""
    v = _tuple(ent, "size", (0.4, 0.4, 1.0), (2, 3))
    if v[0] <= 0 or v[1] <= 0:
        raise _Drop(ent.props["size"], "size must be positive, got %r" % (list(v),))
    return (v[0], v[1])


def _read_bitmap(path, prop):
    """Occupancy of an image as Stage sees it: a pixel darker than mid-grey is solid."""
    from PIL import Image  # local import: PIL is only needed for bitmaps
    if not os.path.isfile(path):
        raise _Drop(prop, "bitmap %s not found: without it the world has no walls; give the path relative to the "
                    "file that names it or to the world file's folder, as Stage does" % path, fatal=True)
    try:
        with Image.open(path) as img:
            img.load()
            if img.mode in ("RGBA", "LA", "PA") or (img.mode == "P" and "transparency" in img.info):
                rgba = np.asarray(img.convert("RGBA"), dtype=np.float32)
                lum = rgba[..., :3].mean(axis=2)
                solid = (lum < 128) & (rgba[..., 3] > 0)
            else:
                lum = np.asarray(img.convert("L"), dtype=np.uint8)
                solid = lum < 128
    except (OSError, ValueError) as err:
        raise _Drop(prop, "bitmap %s cannot be read (%s): without it the world has no walls" % (path, err),
                    fatal=True) from None
    if solid.size == 0:
        raise _Drop(prop, "bitmap %s is empty: without it the world has no walls" % path, fatal=True)
    return solid


_X11 = None


def _x11_colors():
    global _X11
    if _X11 is None:
        _X11 = {}
        for candidate in ("/usr/share/X11/rgb.txt", "/etc/X11/rgb.txt"):
            try:
                with open(candidate, encoding="latin-1") as handle:
                    for line in handle:
                        parts = line.split()
                        if len(parts) >= 4 and parts[0].isdigit():
                            _X11[" ".join(parts[3:]).lower().replace(" ", "")] = \
                                (int(parts[0]), int(parts[1]), int(parts[2]))
                break
            except OSError:
                continue
    return _X11


def color_by_name(name):
    """Stage colour names are X11 names (rgb.txt): 'gray30', 'green' = (0, 255, 0)."""
    key = name.lower().replace(" ", "")
    table = _x11_colors()
    if key in table:
        return table[key]
    if key.startswith(("gray", "grey")) and key[4:].isdigit() and int(key[4:]) <= 100:
        v = int(round(int(key[4:]) * 2.55))
        return (v, v, v)
    from PIL import ImageColor
    return ImageColor.getrgb(name)


def _color(ent, default, log):
    if "color_rgba" in ent.props:
        v = _tuple(ent, "color_rgba", None, (3, 4))
        return tuple(int(round(max(0.0, min(1.0, c)) * 255)) for c in v[:3])
    name = _string(ent, "color", None)
    if name is None:
        return default
    try:
        return color_by_name(name)
    except ValueError:
        log("warn", "%s: unknown colour %r, using %r" % (ent.props["color"].where(), name, default))
        return default
