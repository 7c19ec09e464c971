"""map_server's map loading, without ROS: image + YAML → occupancy values.

Semantics of map_server 1.x (``map_server/src/image_loader.cpp``): the pixel's
colour is the mean of its colour channels (alpha excluded), inverted when
``negate`` is 0: ``occ = (255 - value) / 255``. ``occ > occupied_thresh`` → 100,
``occ < free_thresh`` → 0, otherwise -1 (trinary), a scaled 1..99 (scale) or the
raw value (raw). Image row 0 is the top, so it becomes the map's last row.
"""
import math
import os
from dataclasses import dataclass

import numpy as np

from fleet_sim.errors import MapError

DEFAULT_OCCUPIED_THRESH = 0.65
DEFAULT_FREE_THRESH = 0.196
MODES = ("trinary", "scale", "raw")


@dataclass(frozen=True, eq=False)
class OccupancyMap:
    """``data[row, col]`` int8, row 0 = lowest y (nav_msgs/OccupancyGrid order)."""
    data: np.ndarray
    resolution: float
    origin: tuple          # (x, y, yaw) of the lower-left corner
    image_path: str

    @property
    def width(self):
        return self.data.shape[1]

    @property
    def height(self):
        return self.data.shape[0]


def load_map_image(image_path, resolution, origin=(0.0, 0.0, 0.0), negate=False,
                   occupied_thresh=DEFAULT_OCCUPIED_THRESH, free_thresh=DEFAULT_FREE_THRESH,
                   mode="trinary"):
    """Loads an image as map_server does; raises MapError naming the file and value."""
    from PIL import Image
    try:
        resolution = float(resolution)
    except (TypeError, ValueError):
        raise MapError("%s: resolution must be a number, got %r" % (image_path, resolution)) from None
    if not (resolution > 0 and math.isfinite(resolution)):
        raise MapError("%s: resolution must be > 0, got %r" % (image_path, resolution))
    try:
        occupied_thresh, free_thresh = float(occupied_thresh), float(free_thresh)
    except (TypeError, ValueError):
        raise MapError("%s: thresholds must be numbers, got %r / %r"
                       % (image_path, occupied_thresh, free_thresh)) from None
    if mode not in MODES:
        raise MapError("%s: mode must be one of %s, got %r" % (image_path, "/".join(MODES), mode))
    if not (0.0 <= free_thresh < occupied_thresh <= 1.0):
        raise MapError("%s: need 0 <= free_thresh < occupied_thresh <= 1, got %r / %r"
                       % (image_path, free_thresh, occupied_thresh))
    try:
        origin = tuple(float(v) for v in origin)
    except (TypeError, ValueError):
        raise MapError("%s: origin must be [x, y, yaw], got %r" % (image_path, origin)) from None
    if len(origin) != 3 or not all(math.isfinite(v) for v in origin):
        raise MapError("%s: origin must be [x, y, yaw], got %r" % (image_path, origin))
    if not os.path.isfile(image_path):
        raise MapError("map image %s not found" % image_path)
    try:
        with Image.open(image_path) as img:
            img.load()
            has_alpha = img.mode in ("RGBA", "LA") or "transparency" in img.info
            arr = np.asarray(img.convert("RGBA" if has_alpha else "RGB"), dtype=np.float64)
    except (OSError, ValueError) as err:
        raise MapError("map image %s cannot be read (%s)" % (image_path, err)) from None
    if arr.size == 0:
        raise MapError("map image %s is empty" % image_path)
    color = arr[..., :3].mean(axis=2)
    alpha = arr[..., 3] if has_alpha else np.full(color.shape, 255.0)
    if mode == "raw":
        value = 255.0 - color if negate else color
        data = value.astype(np.int16)
        data = np.clip(data, -128, 127).astype(np.int8) if data.max() > 127 else data.astype(np.int8)
    else:
        if negate:
            color = 255.0 - color
        occ = (255.0 - color) / 255.0
        data = np.full(color.shape, -1, dtype=np.int8)
        data[occ > occupied_thresh] = 100
        data[occ < free_thresh] = 0
        if mode == "scale":
            mid = (occ <= occupied_thresh) & (occ >= free_thresh)
            scaled = 99.0 * (occ - free_thresh) / (occupied_thresh - free_thresh)
            data[mid & (alpha >= 255)] = scaled[mid & (alpha >= 255)].astype(np.int8)
    return OccupancyMap(data=np.ascontiguousarray(data[::-1]), resolution=resolution,
                        origin=origin, image_path=os.path.abspath(image_path))


def load_map_yaml(yaml_path):
    """Loads a map_server YAML (image, resolution, origin, negate, thresholds, mode)."""
    import yaml
    try:
        with open(yaml_path, "r", encoding="utf-8") as handle:
            doc = yaml.safe_load(handle)
    except OSError as err:
        raise MapError("map file %s cannot be read (%s)" % (yaml_path, err.strerror)) from None
    except yaml.YAMLError as err:
        raise MapError("map file %s is not valid YAML (%s)" % (yaml_path, err)) from None
    if not isinstance(doc, dict):
        raise MapError("map file %s must be a mapping with image and resolution" % yaml_path)
    for key in ("image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh"):
        if key not in doc:
            raise MapError("map file %s has no '%s'" % (yaml_path, key))
    image = str(doc["image"])
    if not os.path.isabs(image):
        image = os.path.join(os.path.dirname(os.path.abspath(yaml_path)), image)
    try:
        negate = bool(int(doc["negate"]))
        occ = float(doc["occupied_thresh"])
        free = float(doc["free_thresh"])
    except (TypeError, ValueError):
        raise MapError("map file %s: negate/occupied_thresh/free_thresh must be numbers" % yaml_path) from None
    origin = doc["origin"]
    if not isinstance(origin, (list, tuple)) or len(origin) != 3:
        raise MapError("map file %s: origin must be [x, y, yaw], got %r" % (yaml_path, origin))
    return load_map_image(image, doc["resolution"], origin, negate, occ, free,
                          str(doc.get("mode", "trinary")))


def load_map_args(args):
    """``[map.yaml]`` or ``[image, resolution]``, as map_server's command line."""
    if len(args) == 1:
        return load_map_yaml(args[0])
    if len(args) == 2:
        return load_map_image(args[0], args[1])
    raise MapError("usage: map_server <map.yaml> | map_server <image> <resolution>")
