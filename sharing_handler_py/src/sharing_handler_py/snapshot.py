"""Human-readable YAML snapshot of a handler's obstacle list, written atomically (no ROS)."""
import os
import tempfile

import yaml


def render(robot_name, now, held):
    """YAML text for the HeldObstacles `held` of `robot_name` at clock time `now`."""
    doc = {
        "robot": robot_name,
        "time": round(float(now), 3),
        "count": len(held),
        "obstacles": [{
            "uuid": h.uuid,
            "source": h.source,
            "version": h.version,
            "deadline_s": h.deadline,
            "arrival": round(h.arrival, 3),
            "remaining_s": round(h.remaining, 3),
            "rectangle": [float(v) for v in h.rectangle.as_list()],
            "frame_id": h.frame_id,
            "grid": {"resolution": float(h.geometry.resolution), "origin": [h.geometry.origin_x, h.geometry.origin_y],
                     "size": [h.geometry.size_x, h.geometry.size_y]},
            "cell_count": len(h.cells),
            "cells": list(h.cells),
        } for h in held],
    }
    # Flow style for the innermost lists keeps one obstacle's cells on a few lines.
    return yaml.safe_dump(doc, default_flow_style=None, sort_keys=False, width=100)


def write_atomically(path, text):
    """Writes `text` to `path` so that readers see the old or the new file, never a partial one."""
    directory = os.path.dirname(os.path.abspath(path))
    os.makedirs(directory, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=".%s." % os.path.basename(path), suffix=".tmp", dir=directory)
    try:
        with os.fdopen(fd, "w") as out:
            out.write(text)
            out.flush()
            os.fsync(out.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
