"""Each numeric limit validation.py puts on an incoming obstacle message (outside HandlerParams) just inside and
just outside: the grid (resolution, sizes, uint32 cell count, the tolerance two grids match within), the
rectangle, deadline and version, the uuid's length, the cell count and the index range. Pure, no ROS.
(Version, deadline and stamp ranges of a fleet message are sharing_msgs.obstacle_rules', tested there.)"""
import pytest

from handler_fixtures import GRID, rect
from sharing_handler_py.errors import InvalidMessageError
from sharing_handler_py.validation import (MAX_UUID_LENGTH, Geometry, Obstacle, Rectangle,
                                           check_indexes, check_uuid)

STEP = 1e-9
#: the documented grid tolerance (validation.GEOMETRY_REL_TOL), stated here so that changing it fails a test
REL_TOL = 1e-6


def _accepted(build):
    """(True, value) when ``build()`` returns, (False, reason) when it raises InvalidMessageError."""
    try:
        return True, build()
    except InvalidMessageError as err:
        return False, err.reason


# ------------------------------------------------------------------ Geometry

@pytest.mark.parametrize("resolution,accepted", [(STEP, True), (0.0, False), (-STEP, False)])
def test_grid_resolution_must_be_above_zero(resolution, accepted):
    """Cell indexes are positions divided by the resolution: zero or negative metres per cell is no grid."""
    ok, reason = _accepted(lambda: Geometry(resolution, 0.0, 0.0, 10, 10))
    assert ok == accepted and (ok or reason == "bad_geometry")


@pytest.mark.parametrize("field", ["size_x", "size_y"])
@pytest.mark.parametrize("size,accepted", [(1, True), (0, False)])
def test_grid_sizes_are_at_least_one_cell(field, size, accepted):
    """A grid without cells has no index a message could name."""
    sizes = dict(size_x=10, size_y=10)
    sizes[field] = size
    ok, reason = _accepted(lambda: Geometry(0.05, 0.0, 0.0, sizes["size_x"], sizes["size_y"]))
    assert ok == accepted and (ok or reason == "bad_geometry")


@pytest.mark.parametrize("size_x,size_y,accepted", [
    (65536, 65536, True), (65536, 65537, False), (2 ** 32, 1, True), (2 ** 32 + 1, 1, False)])
def test_grid_cell_count_fits_uint32_indexes(size_x, size_y, accepted):
    """Indexes travel as uint32: a grid of more than 2**32 cells has cells no message can name."""
    ok, reason = _accepted(lambda: Geometry(0.05, 0.0, 0.0, size_x, size_y))
    assert ok == accepted and (ok or reason == "bad_geometry")


@pytest.mark.parametrize("relative,same", [(0.9 * REL_TOL, True), (1.1 * REL_TOL, False)])
@pytest.mark.parametrize("field", ["resolution", "origin_x", "origin_y"])
def test_two_grids_match_within_the_relative_tolerance(field, relative, same):
    """A peer's grid is ours when its resolution and origin agree within GEOMETRY_REL_TOL (float32 on the wire
    rounds them); a grid farther off is another map, whose indexes would mark the wrong cells."""
    values = dict(resolution=GRID.resolution, origin_x=GRID.origin_x, origin_y=GRID.origin_y)
    values[field] *= 1.0 + relative
    other = Geometry(values["resolution"], values["origin_x"], values["origin_y"], GRID.size_x, GRID.size_y)
    assert GRID.matches(other) == same
    assert other.matches(GRID) == same


@pytest.mark.parametrize("offset,same", [(0.9 * REL_TOL, True), (1.1 * REL_TOL, False)])
@pytest.mark.parametrize("field", ["origin_x", "origin_y"])
def test_an_origin_near_zero_matches_within_a_millionth_of_a_cell(field, offset, same):
    """A relative tolerance is no tolerance at zero: there an origin may differ by GEOMETRY_REL_TOL cells."""
    ours = Geometry(0.05, 0.0, 0.0, 4, 4)
    origin = dict(origin_x=0.0, origin_y=0.0)
    origin[field] = offset * 0.05
    assert ours.matches(Geometry(0.05, origin["origin_x"], origin["origin_y"], 4, 4)) == same


# ------------------------------------------------------------------ Rectangle

@pytest.mark.parametrize("axis", ["x", "y"])
@pytest.mark.parametrize("excess,accepted", [(0.0, True), (STEP, False)])
def test_rectangle_min_may_equal_max_but_not_exceed_it(axis, excess, accepted):
    """A rectangle of zero extent (one row or column of cells) is a rectangle; min beyond max is none."""
    lo = dict(x=1.0, y=2.0)
    lo[axis] += excess
    ok, reason = _accepted(lambda: Rectangle(lo["x"], lo["y"], 1.0, 2.0))
    assert ok == accepted and (ok or reason == "malformed")


# ------------------------------------------------------------------ Obstacle

@pytest.mark.parametrize("field", ["deadline", "version"])
@pytest.mark.parametrize("value,accepted", [(0, True), (-1, False)])
def test_obstacle_deadline_and_version_are_not_negative(field, value, accepted):
    """A value type holds what a uint32 deadline or a version could say: a negative one is no message (zero is
    a proposal's version; a fleet message's own lower bounds are sharing_msgs.obstacle_rules')."""
    fields = dict(deadline=30, version=1)
    fields[field] = value
    ok, reason = _accepted(lambda: Obstacle("u", (1,), (), fields["deadline"], rect(0, 0, 1, 1), "robot_1",
                                            GRID, version=fields["version"]))
    assert ok == accepted and (ok or reason == "malformed")


# ------------------------------------------------------------------ check_uuid

@pytest.mark.parametrize("length,accepted", [(MAX_UUID_LENGTH, True), (MAX_UUID_LENGTH + 1, False),
                                             (1, True), (0, False)])
def test_a_uuid_is_1_to_max_uuid_length_characters(length, accepted):
    """An id is kept, logged and sent on: a longer one is no uuid (uuid4 text is 36) and costs memory per
    obstacle; an empty one names nothing."""
    ok, reason = _accepted(lambda: check_uuid("a" * length))
    assert ok == accepted
    if not ok:
        assert reason == ("empty_uuid" if length == 0 else "malformed")


# ------------------------------------------------------------------ check_indexes

def _obstacle(marked, cleared=()):
    return Obstacle("u", tuple(marked), tuple(cleared), 30, rect(0, 0, 1, 1), "robot_1", GRID, version=1)


@pytest.mark.parametrize("count,accepted", [(10, True), (11, False)])
def test_a_message_holds_at_most_max_cells_indexes_marked_and_cleared_together(count, accepted):
    """max_cells_per_message bounds the work one message costs; marked and cleared cells both count."""
    marked = tuple(range(count // 2))
    cleared = tuple(range(100, 100 + count - len(marked)))
    ok, reason = _accepted(lambda: check_indexes(_obstacle(marked, cleared), GRID, 10))
    assert ok == accepted and (ok or reason == "too_many_cells")


@pytest.mark.parametrize("which", ["marked", "cleared"])
@pytest.mark.parametrize("index,accepted", [(0, True), (-1, False),
                                            (GRID.cell_count - 1, True), (GRID.cell_count, False)])
def test_every_index_is_a_cell_of_the_grid(which, index, accepted):
    """Index y * size_x + x names a cell only in 0 .. size_x * size_y - 1: any other would mark no cell, or
    another row's."""
    cells = (5, index)
    obstacle = _obstacle(cells) if which == "marked" else _obstacle((5,), cells)
    ok, reason = _accepted(lambda: check_indexes(obstacle, GRID, 100))
    assert ok == accepted and (ok or reason == "index_out_of_range")
