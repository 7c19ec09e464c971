"""Shared helpers of the pure tests: a fake clock, a recording handler, message builders."""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "src"))
# sharing_msgs' pure helpers without a built workspace; appended, so a sourced workspace wins.
sys.path.append(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "sharing_msgs", "src"))

from sharing_handler_py.logic import SharingHandler  # noqa: E402
from sharing_handler_py.validation import Geometry, Obstacle, Rectangle  # noqa: E402

GRID = Geometry(0.05, -10.0, -5.0, 400, 200)   # 20 m x 10 m
OTHER_GRID = Geometry(0.1, -10.0, -5.0, 200, 100)


def U(name):
    """A UUID standing for a readable test name ("ext-1"): the name's bytes, zero-padded, as
    hex. Order-preserving, so tests that sort by uuid keep their order."""
    raw = name.encode("ascii")
    assert len(raw) <= 16, name
    h = (raw + b"\0" * (16 - len(raw))).hex()
    return "%s-%s-%s-%s-%s" % (h[:8], h[8:12], h[12:16], h[16:20], h[20:])


class FakeClock:
    def __init__(self, now=100.0):
        self.now = now

    def __call__(self):
        return self.now


class Recorder:
    """A handler plus everything it sent, in order."""

    def __init__(self, robot_name="robot_0", geometry=GRID, duration=60, clock=None, uuids=None, **kwargs):
        self.clock = clock or FakeClock()
        self.layer, self.fleet, self.expired, self.events = [], [], [], []
        self.changes = 0
        counter = iter(range(1, 1 << 30))
        factory = (lambda: U("%s-%04d" % (uuids, next(counter)))) if uuids else None

        def to(kind, sink):
            def out(item):
                sink.append(item)
                self.events.append((kind, item))
            return out

        def changed():
            self.changes += 1

        self.handler = SharingHandler(robot_name, self.clock, duration, to("layer", self.layer),
                                      to("fleet", self.fleet), to("expired", self.expired),
                                      geometry=geometry, on_change=changed, uuid_factory=factory,
                                      **kwargs)


def rect(min_x, min_y, max_x, max_y):
    return Rectangle(float(min_x), float(min_y), float(max_x), float(max_y))


def cells_in(rectangle, count=None, geometry=GRID):
    """The first ``count`` (all when None) cell indexes of ``geometry`` whose centre lies inside ``rectangle``:
    cells a message may carry with that rectangle (issue 43: every cell inside its rectangle)."""
    cells = geometry.cells_in(rectangle)
    return tuple(cells if count is None else cells[:count])


def cell_in(rectangle, k, geometry=GRID):
    """The k-th cell (wrapping) inside ``rectangle``: abstract cell numbers of a test made concrete."""
    cells = geometry.cells_in(rectangle)
    return cells[k % len(cells)]


def proposal(cells=(10, 11, 12), rectangle=None, geometry=GRID, source="robot_0"):
    return Obstacle(uuid="", marked=tuple(cells), cleared=(), deadline=0,
                    rectangle=rectangle or rect(-10, -5, -9, -4), source=source, geometry=geometry,
                    frame_id="map")


def update(uuid, marked=(), cleared=(), version=2, source="robot_1", deadline=30, rectangle=None,
           geometry=GRID, stamp=0.0):
    return Obstacle(uuid=uuid, marked=tuple(marked), cleared=tuple(cleared), deadline=deadline,
                    rectangle=rectangle or rect(-10, -5, -9, -4), source=source, geometry=geometry,
                    version=version, frame_id="map", stamp=stamp)


def state(handler):
    """What must agree between robots: everything but local arrival times."""
    return [(h.uuid, h.source, h.version, h.deadline, h.rectangle, h.geometry, h.cells)
            for h in handler.obstacles()]
