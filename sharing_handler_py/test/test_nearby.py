"""The rectangle index behind merging: a query must offer every held rectangle that lies within
the distance (a missed one would leave two obstacles unmerged on one robot and merged on
another), whatever the sequence of adds, moves and removals. Checked against a brute-force scan."""
import math

from hypothesis import given, settings
from hypothesis import strategies as st

from handler_fixtures import Recorder, U, cells_in, proposal, rect, update
from sharing_handler_py.nearby import MAX_BUCKETS_PER_RECTANGLE, RectangleIndex

COORD = st.floats(-60.0, 60.0, allow_nan=False)
SIDE = st.one_of(st.floats(0.0, 3.0), st.floats(3.0, 40.0), st.sampled_from([0.0, 4.0, 8.0]))


@st.composite
def rectangles(draw):
    x, y = draw(COORD), draw(COORD)
    return rect(x, y, x + draw(SIDE), y + draw(SIDE))


OPS = st.lists(st.tuples(st.sampled_from(["put", "put", "remove"]), st.integers(0, 15), rectangles()),
               max_size=60)


@settings(max_examples=300, deadline=None, derandomize=True, database=None)
@given(OPS, rectangles(), st.sampled_from([0.0, 0.5, 3.9, 4.0, 12.0]))
def test_near_offers_every_rectangle_within_the_distance(ops, query, distance):
    index, truth = RectangleIndex(), {}
    for op, key, rectangle in ops:
        if op == "put":
            index.put(key, rectangle)
            truth[key] = rectangle
        else:
            index.remove(key)
            truth.pop(key, None)
    assert len(index) == len(truth)
    offered = index.near(query, distance)
    within = {k for k, r in truth.items() if r.gap(query) <= distance}
    assert within <= offered
    assert offered <= set(truth), "a removed or never added key was offered"


def test_a_huge_rectangle_is_offered_to_every_query_without_a_bucket_per_cell():
    index = RectangleIndex(bucket_size=1.0)
    side = math.sqrt(MAX_BUCKETS_PER_RECTANGLE) * 10
    index.put("huge", rect(-side, -side, side, side))
    index.put("small", rect(500, 500, 501, 501))
    assert index.near(rect(0, 0, 1, 1), 0.0) == {"huge"}
    assert index.near(rect(500, 500, 500.5, 500.5), 0.0) == {"huge", "small"}
    assert index.near(rect(-1e9, -1e9, 1e9, 1e9), 0.0) == {"huge", "small"}
    index.remove("huge")
    assert index.near(rect(0, 0, 1, 1), 0.0) == set()


def test_a_non_positive_bucket_is_refused():
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        try:
            RectangleIndex(bucket_size=bad)
        except ValueError as err:
            assert "bucket_size" in str(err)
        else:
            raise AssertionError("bucket_size %r accepted" % bad)


def test_an_internal_update_that_grows_a_rectangle_next_to_another_merges_them():
    """The layer's own update can grow an obstacle's rectangle (the obstacle grew in view): the
    grown rectangle may now lie within merge_distance of another held obstacle."""
    r = Recorder(merge_distance=0.5)
    other = r.handler.on_proposal(proposal(cells=cells_in(rect(3, 0, 4, 1), 1), rectangle=rect(3, 0, 4, 1)))
    mine = r.handler.on_proposal(proposal(cells=cells_in(rect(0, 0, 1, 1), 2), rectangle=rect(0, 0, 1, 1)))
    assert len(r.handler) == 2
    sent = r.handler.on_internal_update(update(mine.uuid, marked=cells_in(rect(2.6, 0, 2.7, 1), 1), version=2,
                                               source="robot_0", rectangle=rect(0, 0, 2.7, 1)))
    assert sent is not None and sent.rectangle == rect(0, 0, 2.7, 1)
    assert len(r.handler) == 1, "the grown obstacle lies 0.3 m from the other: one obstacle"
    survivor = min(mine.uuid, other.uuid)
    assert r.handler.get(survivor).rectangle == rect(0, 0, 4, 1)
    assert r.handler.counters["merged_obstacles"] == 1



# Merging across a bucket edge: the index keeps rectangles in 4 m buckets (x = 4.0 is an edge), so
# two obstacles just either side of it are in different buckets and only a query widened by
# merge_distance finds the neighbour. merge_distance 0.5: a gap of 0.45 m merges, 0.55 m does not.
EDGE = 4.0


def _either_side(gap):
    """Two 0.45 m squares, the west one ending and the east one starting `gap`/2 from x = 4.0."""
    west = rect(EDGE - gap / 2 - 0.45, 1.0, EDGE - gap / 2, 1.45)
    east = rect(EDGE + gap / 2, 1.0, EDGE + gap / 2 + 0.45, 1.45)
    return west, east


def test_a_proposal_across_a_bucket_edge_merges_just_inside_merge_distance_only():
    for gap, merged in ((0.45, True), (0.55, False)):
        r = Recorder(merge_distance=0.5)
        west, east = _either_side(gap)
        held = r.handler.on_proposal(proposal(cells=cells_in(west), rectangle=west))
        sent = r.handler.on_proposal(proposal(cells=cells_in(east), rectangle=east))
        assert (sent.uuid == held.uuid) is merged, "gap %.2f m, merge_distance 0.5 m" % gap
        assert len(r.handler) == (1 if merged else 2), "gap %.2f m" % gap


def test_held_obstacles_across_a_bucket_edge_merge_just_inside_merge_distance_only():
    for gap, merged in ((0.45, True), (0.55, False)):
        r = Recorder(merge_distance=0.5)
        west, east = _either_side(gap)
        for name, rectangle in (("west", west), ("east", east)):
            assert r.handler.on_external(update(U(name), marked=cells_in(rectangle), version=1,
                                                source="robot_1", rectangle=rectangle)) is True
        assert len(r.handler) == (1 if merged else 2), "gap %.2f m, merge_distance 0.5 m" % gap
        assert r.handler.counters["merged_obstacles"] == (1 if merged else 0)
