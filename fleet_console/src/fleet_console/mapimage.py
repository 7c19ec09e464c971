"""The map the console draws under the fleet: from the fleet's map server (a nav_msgs/OccupancyGrid's fields)
or from a map_server YAML file and its image. No rospy here: the node hands the grid's fields in.

A map is a PNG (row 0 at the top, i.e. the grid's last row) and its geometry; a bad map raises MapError
naming what is wrong, which the page shows instead of the map (the console keeps running).
"""
import io
import math
import os

MAX_CELLS = 10000 * 10000


class MapError(ValueError):
    """A map the console cannot draw; the message says why."""


class ConsoleMap:
    """A rendered map: png bytes and the geometry the page places it with."""

    def __init__(self, png, resolution, origin_x, origin_y, width, height, source):
        self.png, self.resolution = png, resolution
        self.origin_x, self.origin_y, self.width, self.height, self.source = origin_x, origin_y, width, height, source

    def meta(self):
        return {"resolution": self.resolution, "origin": [self.origin_x, self.origin_y], "width": self.width,
                "height": self.height, "source": self.source, "url": "/map.png"}


def _check_geometry(resolution, origin_x, origin_y, width, height, what):
    for name, value in (("resolution", resolution), ("origin x", origin_x), ("origin y", origin_y)):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise MapError("%s: %s %r is not a finite number" % (what, name, value))
    if resolution <= 0:
        raise MapError("%s: resolution %r must be > 0" % (what, resolution))
    if not (isinstance(width, int) and isinstance(height, int)) or width < 1 or height < 1 \
            or width * height > MAX_CELLS:
        raise MapError("%s: size %r x %r must be 1.. cells a side, at most %d cells" % (what, width, height, MAX_CELLS))


def _png(image):
    out = io.BytesIO()
    image.save(out, format="PNG", optimize=False)
    return out.getvalue()


def from_grid(data, resolution, origin_x, origin_y, width, height, source="/map"):
    """An OccupancyGrid's cells (row-major, row 0 at origin y): free white, occupied black, unknown grey."""
    from PIL import Image
    what = "map %s" % source
    _check_geometry(resolution, origin_x, origin_y, width, height, what)
    if len(data) != width * height:
        raise MapError("%s: %d cells for a %d x %d grid" % (what, len(data), width, height))
    lut = bytearray(256)
    for value in range(256):
        signed = value - 256 if value > 127 else value
        lut[value] = 205 if signed < 0 else 255 - int(255 * min(signed, 100) / 100)
    raw = bytes(data) if isinstance(data, (bytes, bytearray)) else bytes((v & 0xFF) for v in data)
    image = Image.frombytes("L", (width, height), raw.translate(bytes(lut)))
    return ConsoleMap(_png(image.transpose(Image.FLIP_TOP_BOTTOM)), float(resolution), float(origin_x),
                      float(origin_y), width, height, source)


def from_yaml(path):
    """A map_server YAML file (image, resolution, origin) and its image, drawn as it is."""
    import yaml
    from PIL import Image
    what = "map file %s" % path
    try:
        with open(path) as handle:
            spec = yaml.safe_load(handle)
    except OSError as err:
        raise MapError("%s: %s" % (what, err.strerror or err)) from None
    except yaml.YAMLError as err:
        raise MapError("%s is not YAML: %s" % (what, str(err).splitlines()[0])) from None
    if not isinstance(spec, dict) or "image" not in spec or "resolution" not in spec or "origin" not in spec:
        raise MapError("%s: needs image, resolution and origin (a map_server YAML file)" % what)
    origin = spec["origin"]
    if not isinstance(origin, list) or len(origin) < 2:
        raise MapError("%s: origin %r must be [x, y, yaw]" % (what, origin))
    image_path = os.path.join(os.path.dirname(os.path.abspath(path)), str(spec["image"]))
    try:
        with Image.open(image_path) as image:
            if image.width * image.height > MAX_CELLS:   # before decoding: a header may claim any size
                raise MapError("%s: image %s is %d x %d pixels, more than %d cells"
                               % (what, spec["image"], image.width, image.height, MAX_CELLS))
            image.load()
            grey = image.convert("L")
    except (OSError, ValueError, Image.DecompressionBombError) as err:
        if isinstance(err, MapError):
            raise
        raise MapError("%s: image %s cannot be read: %s" % (what, spec["image"], err)) from None
    _check_geometry(spec["resolution"], origin[0], origin[1], grey.width, grey.height, what)
    return ConsoleMap(_png(grey), float(spec["resolution"]), float(origin[0]), float(origin[1]), grey.width,
                      grey.height, path)
