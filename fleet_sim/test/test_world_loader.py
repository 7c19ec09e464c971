"""World loader: the two real worlds as they are, macros, and broken files."""
import math
import os

import pytest

import sim_test_helpers as h
from fleet_sim.errors import WorldError, WorldSyntaxError
from fleet_sim.world import load_world, require_robots
from fleet_sim.world.parser import parse_world


def quiet(level, msg):
    pass


def test_willow_world_loads_as_written():
    w = load_world(h.WILLOW, log=quiet)
    assert w.problems == []
    assert w.resolution == pytest.approx(0.02)
    assert w.interval_sim == pytest.approx(0.1)
    assert [r.name for r in w.robots] == ["pr2_0", "pr2_1"]
    r0, r1 = w.robots
    assert r0.color == (0, 0, 255) and r1.color == (0, 255, 0)       # blue, green (X11 names)
    assert r0.drive == "omni"
    assert r0.size == pytest.approx((0.65, 0.65)) and r0.origin == pytest.approx((-0.05, 0.0))
    assert r0.pose == pytest.approx((-21.67, 47.12, math.radians(28.166)))
    (laser,) = r0.rangers
    assert laser.samples == 1081
    assert math.degrees(laser.fov) == pytest.approx(270.25)
    assert laser.range_max == pytest.approx(30.0)                       # range_max honoured
    assert laser.pose == pytest.approx((0.275, 0.0, 0.0))
    # stage_ros publishes base_link -> base_laser_link at z 0.25 here (the recorded bag's /tf): the pr2's
    # size z 0.25 plus the ranger's pose z 0
    assert r0.height == pytest.approx(0.25) and laser.z == pytest.approx(0.0)
    (fp,) = w.floorplans
    assert fp.name == "willow" and fp.boundary
    assert fp.pose == pytest.approx((-26.3, 29.2, math.pi / 2))
    assert fp.size == pytest.approx((58.4, 52.6))
    assert fp.occupied.shape == (526, 584)
    (block,) = w.blocks
    assert block.name == "block:0" and block.color == (255, 0, 0)
    assert block.size == pytest.approx((0.5, 0.5))
    assert block.pose[:2] == pytest.approx((-24.269, 48.001))


def test_willow_stage43_compat_uses_stage_default_range():
    lines = []
    w = load_world(h.WILLOW, stage43_range_compat=True, log=lambda lvl, msg: lines.append((lvl, msg)))
    assert w.robots[0].rangers[0].range_max == pytest.approx(5.0)
    assert w.robots[0].rangers[0].samples == 1081
    assert any(lvl == "warn" and "range_max" in msg and "willow-pr2-multi.world:10" in msg
               for lvl, msg in lines)


def test_simple_world_with_includes_and_nested_macros():
    w = load_world(h.SIMPLE, log=quiet)
    assert w.problems == []
    assert w.speedup == 0.0
    assert len(w.files) == 4                                   # world + 3 includes
    assert [r.name for r in w.robots] == ["r0", "r1"]
    r0 = w.robots[0]
    assert r0.drive == "diff" and r0.color == (255, 0, 0)     # inherited from pioneer_base
    assert r0.size == pytest.approx((0.44, 0.38))             # from pioneer2dx_base_no_sonar
    assert r0.origin == pytest.approx((-0.04, 0.0))
    sonar, sick = r0.rangers                                   # as stage_ros: base_scan_0, _1
    assert sonar.samples == 1 and sonar.range_max == pytest.approx(5.0)
    assert math.degrees(sonar.fov) == pytest.approx(15.0)
    assert sonar.pose == pytest.approx((0.075, 0.130, math.pi / 2))
    assert sick.samples == 180 and sick.range_max == pytest.approx(8.0)
    assert math.degrees(sick.fov) == pytest.approx(180.0)
    (cave,) = w.floorplans
    assert cave.size == pytest.approx((16.0, 16.0)) and cave.occupied.shape == (500, 500)
    assert not cave.obstacle          # map.inc's floorplan has obstacle_return 0
    assert cave.visible


def test_macro_inheritance_override_and_children():
    lines = []
    w = load_world(os.path.join(h.DATA, "macros.world"), log=lambda lvl, msg: lines.append((lvl, msg)))
    a, b = w.robots
    assert a.color == (255, 165, 0)                  # midbot overrides basebot's red
    assert b.color == (0, 0, 255)                    # the instance overrides the macros
    assert a.drive == "diff" and b.drive == "omni"
    assert a.size == pytest.approx((0.6, 0.4))       # topbot overrides basebot
    (laser,) = a.rangers                             # Stage-3 'laser' spelling
    assert laser.range_max == pytest.approx(20.0)    # long_laser overrides base_laser
    assert laser.samples == 91 and math.degrees(laser.fov) == pytest.approx(90.0)
    assert laser.pose == pytest.approx((0.2, 0.0, math.pi / 2))
    assert [blk.name for blk in w.blocks] == ["crate:0", "big"]
    assert w.blocks[1].size == pytest.approx((2.0, 2.0))
    assert w.blocks[0].pose[2] == pytest.approx(math.radians(30))
    assert any(lvl == "debug" and "unknown_thing" in msg and "macros.world:15" in msg for lvl, msg in lines)


def test_parser_keeps_the_line_of_each_property():
    parsed = parse_world(h.WILLOW)
    floor = [e for e in parsed.entities if e.kind == "floorplan"][0]
    assert floor.props["pose"].line == 65
    assert floor.props["color"].line == 31             # inherited from the define
    assert parsed.props["interval_sim"].value == 100.0


@pytest.mark.parametrize("name, line, reason", [
    ("unbalanced.world", 6, "missing ')'"),
    ("unterminated_string.world", 3, "unterminated string"),
    ("missing_include.world", 2, "no_such_file.inc"),
    ("undefined_macro.world", 3, "unknown model type 'robotx'"),
    ("property_without_value.world", 4, "property 'size' needs a value"),
    ("recursive_macro.world", 1, "defined in terms of itself"),
    ("bad_character.world", 3, "unexpected character ';'"),
    ("extra_paren.world", 1, "unbalanced ')'"),
    ("word_in_tuple.world", 3, "found word 'foo'"),
])
def test_malformed_file_names_file_line_and_reason(name, line, reason):
    path = os.path.join(h.DATA, "broken", name)
    with pytest.raises(WorldSyntaxError) as info:
        load_world(path, log=quiet)
    err = info.value
    assert err.path == path and err.line == line
    assert reason in str(err)
    assert str(err).startswith("%s:%d: " % (path, line))


def test_missing_world_file():
    with pytest.raises(WorldSyntaxError, match="cannot read world file"):
        load_world(os.path.join(h.DATA, "no_such.world"), log=quiet)


def test_bad_values_drop_only_the_bad_models():
    path = os.path.join(h.DATA, "broken", "bad_values.world")
    errors = []
    w = load_world(path, log=lambda lvl, msg: errors.append(msg) if lvl == "error" else None)
    assert [b.name for b in w.blocks] == ["good_block"]
    assert [r.name for r in w.robots] == ["ok", "zero_samples"]
    assert len(w.robots[0].rangers) == 1
    assert len(w.robots[1].rangers) == 1          # the macro's ranger stays, the bad one goes
    assert errors == w.problems and len(w.problems) == 5
    expect = [(6, "'pose' must be [3 or 4 numbers], got (1.0, 2.0)", "'bad_pose'"),
              (7, "'pose' must be [3 or 4 numbers], got 'here'", "'text_pose'"),
              (8, "size must be positive, got [-1.0, 1.0]", "'negative'"),
              (10, "samples must be a whole number >= 1, got 0", "zero_samples"),
              (11, "drive must be \"diff\" or \"omni\", got 'car'", "'bad_drive'")]
    for problem, (line, reason, who) in zip(w.problems, expect):
        assert problem.startswith("%s:%d: " % (path, line)), problem
        assert reason in problem and who in problem


def test_strict_mode_raises_on_the_first_bad_model():
    path = os.path.join(h.DATA, "broken", "bad_values.world")
    with pytest.raises(WorldError) as info:
        load_world(path, strict=True, log=quiet)
    assert info.value.line == 6 and "'pose' must be" in str(info.value)


@pytest.mark.parametrize("strict", [False, True])
def test_a_missing_floorplan_bitmap_is_refused_not_simulated_without_walls(strict):
    path = os.path.join(h.DATA, "broken", "missing_bitmap.world")
    with pytest.raises(WorldError) as info:
        load_world(path, strict=strict, log=quiet)
    assert info.value.path == path and info.value.line == 3
    assert "does_not_exist.png not found: without it the world has no walls" in str(info.value)


@pytest.mark.parametrize("count, refused", [(0, False), (2, False), (3, True)])
def test_a_world_with_fewer_robots_than_driven_is_refused(count, refused):
    path = os.path.join(h.DATA, "room.world")
    world = load_world(path, log=quiet)
    assert len(world.robots) == 2
    if not refused:
        require_robots(world, count)
        return
    with pytest.raises(WorldError) as info:
        require_robots(world, count)
    assert str(info.value).startswith(path + ": holds 2 robot(s)")
    assert "but 3 are to be driven (robots:=3)" in str(info.value)


def test_bad_world_level_value_is_an_error(tmp_path):
    p = tmp_path / "bad_res.world"
    p.write_text("# comment\nresolution -0.5\n")
    with pytest.raises(WorldError, match=r"bad_res.world:2: 'resolution' must be > 0"):
        load_world(str(p), log=quiet)


@pytest.mark.parametrize("sensor, reason", [
    ("range [5 1] fov 90 samples 10", "range must satisfy 0 <= min < max"),
    ("range [0 10] fov 0 samples 10", "fov must be in (0, 360]"),
    ("range [0 10] fov 90 samples 2.5", "samples must be a whole number"),
    ("range [0 10 3] fov 90 samples 10", "'range' must be [2 numbers]"),
])
def test_bad_sensor_values(tmp_path, sensor, reason):
    p = tmp_path / "s.world"
    p.write_text("position( name \"r\"\n  ranger( sensor( %s ) )\n)\n" % sensor)
    w = load_world(str(p), log=quiet)
    assert len(w.robots) == 1 and w.robots[0].rangers == ()
    assert len(w.problems) == 1 and reason in w.problems[0] and "s.world:" in w.problems[0]


# --- Stage 4.3 syntax (issue 28): Stage 4.3 silently ignores the Stage-3 spellings; we say so ---------

def load_with_lines(path, **kwargs):
    lines = []
    world = load_world(str(path), log=lambda lvl, msg: lines.append((lvl, msg)), **kwargs)
    return world, [msg for lvl, msg in lines if lvl == "warn"]


def test_stage3_range_max_is_read_with_a_warning_naming_robot_value_and_the_fix():
    w, warns = load_with_lines(h.WILLOW)
    assert w.robots[0].rangers[0].range_max == pytest.approx(30.0)
    (first,) = [m for m in warns if "pr2_0" in m]
    for shown in ("willow-pr2-multi.world:10", "robot pr2_0 (robot_0)", "range_max 30", "Stage 4.3 ignores it",
                  "[0 5]", "range [ 0 30 ]"):
        assert shown in first, (shown, first)
    assert len([m for m in warns if "range_max" in m]) == 2        # once per robot


@pytest.mark.parametrize("compat", [False, True])
def test_range_wins_over_range_max_as_in_stage(tmp_path, compat):
    p = tmp_path / "both.world"
    p.write_text('position( name "r"\n  ranger( sensor( range [ 0.1 12 ]\n range_max 30 fov 90 samples 10 ) )\n)\n')
    w, warns = load_with_lines(p, stage43_range_compat=compat)
    (laser,) = w.robots[0].rangers
    assert (laser.range_min, laser.range_max) == pytest.approx((0.1, 12.0))
    assert any("both.world:3" in m and "range_max 30" in m and "ignored" in m for m in warns), warns


def test_stage43_sensor_defaults_apply_to_each_sensor(tmp_path):
    """Stage 4.3's Sensor(): range [0 5], fov 0.1 rad, 1 sample, whatever the ranger around it says."""
    p = tmp_path / "defaults.world"
    p.write_text('position( name "r"\n  ranger( sensor( ) )\n)\n')
    w, warns = load_with_lines(p, stage43_range_compat=True)
    (laser,) = w.robots[0].rangers
    assert (laser.range_min, laser.range_max, laser.samples) == (0.0, 5.0, 1)
    assert laser.fov == pytest.approx(0.1)
    assert warns == []


def test_ranger_properties_outside_a_sensor(tmp_path):
    p = tmp_path / "bare.world"
    p.write_text('position( name "r"\n  ranger( range [ 0 20 ] fov 180 samples 181 )\n)\n')
    w, warns = load_with_lines(p)
    assert w.robots[0].rangers[0].range_max == pytest.approx(20.0)
    assert any("bare.world:2" in m and "robot r" in m and "only inside sensor" in m for m in warns), warns
    w, warns = load_with_lines(p, stage43_range_compat=True)       # Stage 4.3: a ranger without a sensor
    assert w.robots[0].rangers == ()
    assert any("no sensor and no scan" in m for m in warns), warns


def test_stage3_laser_model_is_refused_in_stage43_mode():
    path = os.path.join(h.DATA, "macros.world")
    w, warns = load_with_lines(path)
    assert w.robots[0].rangers[0].range_max == pytest.approx(20.0)
    assert any("'laser' model" in m and "robot a" in m for m in warns)
    w, _ = load_with_lines(path, stage43_range_compat=True)
    assert w.robots[0].rangers == () and any("Unknown model type laser" in p for p in w.problems)
