"""pytest for the pybind11 module: NumPy in and out, errors as ValueError, state intact."""
import numpy as np
import pytest

from sharing_layer_cpp import core


def grid():
    return core.GridGeometry(0.1, 0.0, 0.0, 40, 40)


def make_core(**params):
    return core.SharingCore(grid(), core.LayerParams(robot_name="robot_0", **params))


def update(uuid="a", marked=(), cleared=(), version=1, source="robot_1", rect=(1.0, 1.0, 2.0, 2.0), geometry=None):
    return core.ObstacleUpdate(uuid, np.array(marked, dtype=np.uint32), np.array(cleared, dtype=np.uint32), 60,
                               list(rect), source, geometry or grid(), version)


def test_geometry_round_trip_and_outside():
    g = grid()
    assert g.world_to_map(1.23, 0.05) == (12, 0)
    assert g.world_to_map(-0.01, 0.5) is None
    assert g.world_to_map(float("nan"), 0.5) is None
    assert g.map_to_world(12, 0) == pytest.approx((1.25, 0.05))


def test_raytrace_line_matches_costmap_bresenham():
    assert core.raytrace_line(0, 0, 6, 2, 7, 3).tolist() == [0, 1, 9, 10, 11, 19, 20]
    assert core.raytrace_line(0, 0, 6, 0, 7, 1, max_length=3).tolist() == [0, 1, 2, 3]
    with pytest.raises(ValueError, match="inside"):
        core.raytrace_line(0, 0, 9, 0, 7, 1)


def test_raycast_ranges_hit_wall_and_max_range():
    occ = np.zeros((100, 100), np.uint8)
    occ[:, 80] = 1  # wall at x = 4.0 m
    ranges = core.raycast_ranges(occ, 0.05, 0.0, 0.0, 1.0, 2.5, np.array([0.0, np.pi, np.pi / 2]), 0.1, 30.0)
    assert ranges.dtype == np.float32
    assert ranges.tolist() == pytest.approx([3.0, 30.0, 30.0])
    with pytest.raises(ValueError, match="min_range"):
        core.raycast_ranges(occ, 0.05, 0.0, 0.0, 1.0, 2.5, np.array([0.0]), 5.0, 1.0)


def test_scan_to_points_drops_invalid_readings():
    ranges = np.array([1.0, np.nan, np.inf, 0.01, 2.0])
    pts = core.scan_to_points(ranges, 0.0, np.pi / 2, 0.05, 30.0, 1.0, 1.0, 0.0)
    assert pts.shape == (2, 3)
    assert pts[0].tolist() == pytest.approx([2.0, 1.0, 0.0])
    assert pts[1].tolist() == pytest.approx([3.0, 1.0, 0.0])  # 5th beam: angle 2 pi, 2 m


def test_process_scan_marks_and_returns_numpy():
    c = make_core()
    out = c.process_scan((0.05, 0.05, 0.0), np.array([[0.55, 0.05, 0.0]]), 1.0)
    assert out.marked.tolist() == [5]
    assert c.obstacle_grid()[0, 5] == core.LETHAL_OBSTACLE
    assert c.shareable_cells().tolist() == [5]


def test_obstacle_grid_is_a_live_view():
    c = make_core()
    view = c.obstacle_grid()
    c.process_scan((0.05, 0.05, 0.0), np.array([[0.55, 0.05, 0.0]]), 1.0)
    assert view[0, 5] == core.LETHAL_OBSTACLE
    c.reset_obstacle_layer()
    assert view[0, 5] == core.FREE_SPACE


def test_apply_shared_monitoring_and_draw():
    c = make_core()
    cells = [15 * 40 + 15, 15 * 40 + 16]
    assert c.apply_shared(update(marked=cells), 0.0).ok
    master = np.zeros((40, 40), np.uint8)
    c.draw_shared(master)
    assert np.count_nonzero(master) == 2
    # A beam through both cells to a farther wall is evidence of free space; three such scans over a second
    # (clearing_scans, clearing_time) clear them: an update with our name and version 2.
    beam = np.array([[2.55, 1.55, 0.0]])
    assert not c.process_scan((0.55, 1.55, 0.0), beam, 2.0).updates
    assert not c.process_scan((0.55, 1.55, 0.0), beam, 2.5).updates
    out = c.process_scan((0.55, 1.55, 0.0), beam, 3.0)
    assert len(out.updates) == 1
    upd = out.updates[0]
    assert (upd.uuid, upd.source, upd.version) == ("a", "robot_0", 2)
    assert sorted(upd.cleared.tolist()) == cells
    assert c.shared_cells("a").size == 0
    assert c.expire("a") and not c.expire("a")


def test_bad_updates_rejected_with_reason_and_state_intact():
    c = make_core()
    assert c.apply_shared(update(marked=[5]), 0.0)
    bad = c.apply_shared(update(marked=[40 * 40 + 1], version=2), 1.0)
    assert not bad.ok and "outside" in bad.error
    other = c.apply_shared(update(geometry=core.GridGeometry(0.05, 0, 0, 80, 80), version=3), 1.0)
    assert not other.ok and "differs" in other.error
    assert c.shared_cells("a").tolist() == [5]
    # Negative or fractional indexes must not wrap into valid cells.
    with pytest.raises(ValueError, match="out of range"):
        core.ObstacleUpdate("b", np.array([-1]), [], 60, [1.0, 1.0, 2.0, 2.0], "robot_1", grid(), 1)
    with pytest.raises(ValueError, match="integers"):
        core.ObstacleUpdate("b", np.array([1.5]), [], 60, [1.0, 1.0, 2.0, 2.0], "robot_1", grid(), 1)
    with pytest.raises(ValueError, match="min_x > max_x"):
        update(rect=(2.0, 0.0, 1.0, 1.0))


def test_bad_parameters_and_inputs_raise_value_error():
    with pytest.raises(ValueError, match="obstacle_range"):
        core.LayerParams(obstacle_range=float("nan"))
    with pytest.raises(ValueError, match="raytrace_range"):
        core.LayerParams(raytrace_range=-1.0)
    with pytest.raises(ValueError, match="proposal_strategy"):
        core.LayerParams(proposal_strategy="diagonal")
    c = make_core()
    with pytest.raises(ValueError, match="points"):
        c.process_scan((0.0, 0.0, 0.0), np.zeros((3, 2)), 0.0)
    with pytest.raises(ValueError, match="cells"):
        c.set_static_map(np.zeros(10, np.uint8))
    # A zero-beam scan and an origin off the map are not errors: nothing is cleared.
    assert c.process_scan((0.0, 0.0, 0.0), np.zeros((0, 3)), 0.0).marked.size == 0
    assert not c.process_scan((-9.0, 0.0, 0.0), np.array([[0.55, 0.05, 0.0]]), 0.0).origin_in_map


def test_trigger_and_proposals_from_python():
    c = make_core(trigger_debounce=2.0)
    c.process_scan((2.05, 2.05, 0.0), np.array([[2.55, 1.95, 0.0], [2.55, 2.05, 0.0], [1.45, 2.05, 0.0]]), 1.0)
    assert c.signal_stuck(1.0) and not c.signal_stuck(1.5)
    proposals = c.propose(2.05, 2.05)
    assert [p.cells.size for p in proposals] == [2, 1]
    assert proposals[0].rectangle == pytest.approx([2.5, 1.9, 2.6, 2.1])


def test_evidence_parameters_and_scan_evidence_lists():
    p = core.LayerParams(clearing_margin=0.2, clearing_scans=2, clearing_time=0.0, clearing_neighbours=0,
                         trigger_memory=10.0, trigger_radius=3.0, inscribed_radius=0.3)
    assert (p.clearing_margin, p.clearing_scans, p.clearing_time, p.clearing_neighbours) == (0.2, 2, 0.0, 0)
    assert (p.trigger_memory, p.trigger_radius, p.inscribed_radius) == (10.0, 3.0, 0.3)
    for name, value in (("clearing_margin", -0.1), ("clearing_scans", 0), ("clearing_time", float("inf")),
                        ("trigger_memory", float("nan")), ("trigger_radius", -1.0), ("inscribed_radius", -1.0),
                        ("clearing_neighbours", 5000)):
        with pytest.raises(ValueError, match=name):
            core.LayerParams(**{name: value})
    c = core.SharingCore(grid(), p)
    assert c.apply_shared(update(marked=[15 * 40 + 15, 15 * 40 + 22]), 0.0).ok
    # Endpoint in cell 22 at 1.7 m: cell 15 lies 0.7 m before it (evidence), cell 22 holds the endpoint (hit).
    out = c.process_scan((0.55, 1.55, 0.0), np.array([[2.25, 1.55, 0.0]]), 1.0)
    assert out.watched_free.tolist() == [15 * 40 + 15]
    assert out.watched_hit.tolist() == [15 * 40 + 22]
    out = c.process_scan((0.55, 1.55, 0.0), np.array([[2.25, 1.55, 0.0]]), 1.1)
    assert [u.cleared.tolist() for u in out.updates] == [[15 * 40 + 15]]


def test_unknown_map_memory_and_triggers_from_python():
    c = make_core()
    unknown = np.zeros((40, 40), np.uint8)
    unknown[:, 30:] = 1  # x >= 3.0 m is unknown
    c.set_unknown_map(unknown)
    with pytest.raises(ValueError, match="cells"):
        c.set_unknown_map(np.zeros(7, np.uint8))
    # (2.55, 2.05) is known free; (3.15, 2.05) is unknown: never shareable, never remembered.
    c.process_scan((2.05, 2.05, 0.0), np.array([[2.55, 2.05, 0.0], [3.15, 2.05, 0.0]]), 1.0)
    assert c.shareable_cells().tolist() == [20 * 40 + 25]
    assert c.remembered_cells().tolist() == [20 * 40 + 25]
    report = c.trigger("recovery_status", 1.0, 2.05, 2.05)
    assert (report.source, report.reason, report.log) == ("recovery_status", "proposed", True)
    assert [p.cells.tolist() for p in report.proposals] == [[20 * 40 + 25]]
    again = c.trigger("stuck_feedback", 1.1, 2.05, 2.05)
    assert again.reason == "debounced" and "stuck_feedback" in again.message
    with pytest.raises(ValueError, match="trigger source"):
        c.trigger("bogus", 5.0, 0.0, 0.0)
    c.set_unknown_map(None)
    c.process_scan((2.05, 2.05, 0.0), np.array([[3.15, 2.05, 0.0]]), 2.0)
    assert 20 * 40 + 31 in c.remembered_cells().tolist()


def test_plan_trigger_from_python():
    c = make_core()
    xs = np.arange(0.05, 3.95, 0.05)
    c.set_plan(np.stack([xs, np.full_like(xs, 2.05)], axis=1))
    assert c.plan_length == xs.size
    assert c.check_plan(1.05, 2.05, 1.0).reason == "none"  # no scan yet
    c.process_scan((1.05, 2.05, 0.0), np.array([[2.55, 2.05, 0.0], [2.55, 3.55, 0.0]]), 1.0)
    report = c.check_plan(1.05, 2.05, 1.0)
    assert (report.source, report.reason) == ("plan_blocked", "proposed")
    assert [p.cells.tolist() for p in report.proposals] == [[20 * 40 + 25]]  # not the cell 1.5 m off the plan
    with pytest.raises(ValueError, match="x, y"):
        c.set_plan(np.zeros(4))
    c.set_plan(np.zeros((0, 2)))
    assert c.plan_length == 0
