"""Every world file of the repository, read the way Stage 4.3 reads it (issue 28).

The facility worlds once wrote their laser as `sensor( range_max 30.0 ... )`, Stage 3's spelling:
Stage 4.3's ranger reads only `range [min max]` and silently ignores the rest, so under real
stageros those lasers reached 5 m, while our simulator (which honoured range_max) and
launch/README.md said 30 m. Here each world is loaded with the simulator's Stage 4.3 reading
(`stage43_range_compat`): no Stage-3 spelling may be left (the loader WARNs on each), every laser
has the range the table below gives it, and our simulator's own reading of the world is the same,
so what runs here is what runs in Stage. A new world file must be added to the table.
"""
import fnmatch
import os

import pytest

from fleet_sim.world import load_world

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
NOT_SOURCES = {"catkin_ws", "test_results", "out", "node_modules", "build", "devel"}

# (min, max) m of every laser, by world file (repository-relative, fnmatch patterns)
LASER_RANGE = {
    "launch/worlds/facility_*.world": (0.0, 30.0),     # the tutorials' 30 m laser (launch/README.md)
    "launch/worlds/deadend_*.world": (0.0, 30.0),
    "launch/worlds/corridors_*.world": (0.0, 30.0),
    "sharing_replay/test/replay/data/corridor.world": (0.0, 30.0),
    "sharing_replay/test/replay/data/corridors_5_coarse.world": (0.0, 30.0),
    "fleet_sim/test/data/room.world": (0.0, 30.0),
}
# Worlds that are not Stage 4.3 on purpose, each with the test that needs it so.
NOT_STAGE43 = {
    "fleet_sim/test/data/broken/*.world": "malformed files for the parser's error tests (test_world_loader.py)",
    "fleet_sim/test/data/macros.world": "the Stage-3 'laser' model, for the loader's macro and Stage-3 tests",
    "data/stage_worlds/*/*.world": "reference data as published (the tutorials' Willow world in Stage-3 spelling, "
                                   "Stage's simple.world), read as they are by fleet_sim's tests",
}


def world_files():
    found = []
    for folder, subfolders, names in os.walk(ROOT):
        subfolders[:] = sorted(d for d in subfolders if not d.startswith(".") and d not in NOT_SOURCES)
        found += [os.path.relpath(os.path.join(folder, n), ROOT) for n in names if n.endswith(".world")]
    return sorted(found)


def matching(rel, table):
    return [pattern for pattern in table if fnmatch.fnmatchcase(rel, pattern)]


STAGE43_WORLDS = [rel for rel in world_files() if not matching(rel, NOT_STAGE43)]


def test_the_repository_has_its_worlds_and_every_exception_still_exists():
    assert len(STAGE43_WORLDS) >= 33, STAGE43_WORLDS  # 10 facility, 10 dead-end, 10 two-corridor, corridor, room, coarse
    for pattern in list(LASER_RANGE) + list(NOT_STAGE43):
        assert [rel for rel in world_files() if fnmatch.fnmatchcase(rel, pattern)], "%s matches no world" % pattern


@pytest.mark.parametrize("rel", STAGE43_WORLDS)
def test_world_reads_as_stage_43_reads_it_with_its_laser_range(rel):
    patterns = matching(rel, LASER_RANGE)
    assert len(patterns) == 1, "%s: add its laser range to LASER_RANGE in %s" % (rel, os.path.basename(__file__))
    expected = LASER_RANGE[patterns[0]]
    lines = []
    stage = load_world(os.path.join(ROOT, rel), stage43_range_compat=True, strict=True,
                       log=lambda level, msg: lines.append(msg) if level in ("warn", "error") else None)
    assert lines == [] and stage.problems == [], "%s is not in Stage 4.3 syntax:\n%s" % (rel, "\n".join(lines))
    assert stage.robots, "%s has no robot" % rel
    for robot in stage.robots:
        assert robot.rangers, "%s: robot %s has no laser in Stage 4.3" % (rel, robot.name)
        for ranger in robot.rangers:
            assert (ranger.range_min, ranger.range_max) == pytest.approx(expected), \
                "%s: robot %s's laser reaches [%g %g] m in Stage 4.3, not [%g %g]" % (
                    rel, robot.name, ranger.range_min, ranger.range_max, expected[0], expected[1])
    ours = load_world(os.path.join(ROOT, rel), strict=True, log=lambda level, msg: None)
    assert [r.rangers for r in ours.robots] == [r.rangers for r in stage.robots], \
        "%s: our simulator reads its lasers differently from Stage 4.3" % rel
