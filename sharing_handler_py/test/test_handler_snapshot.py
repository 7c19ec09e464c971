"""The YAML snapshot: readable content and an atomic write."""
import os

import pytest
import yaml

from handler_fixtures import Recorder, U, cells_in, proposal, rect, update
from sharing_handler_py import snapshot


def test_snapshot_lists_every_obstacle_with_its_cells_and_times():
    r = Recorder(duration=60, uuids="r0")
    shared = r.handler.on_proposal(proposal(cells=cells_in(rect(0, 0, 1, 1), 2), rectangle=rect(0, 0, 1, 1)))
    r.handler.on_external(update(U("ext-1"), marked=(5, 3), version=2, source="robot_1", deadline=30))
    r.clock.now += 10
    doc = yaml.safe_load(snapshot.render("robot_0", r.clock.now, r.handler.obstacles()))
    assert doc["robot"] == "robot_0" and doc["count"] == 2
    by_uuid = {o["uuid"]: o for o in doc["obstacles"]}
    assert by_uuid[U("ext-1")]["cells"] == [3, 5] and by_uuid[U("ext-1")]["remaining_s"] == 20.0
    assert by_uuid[shared.uuid]["source"] == "robot_0"
    assert by_uuid[shared.uuid]["rectangle"] == [0.0, 0.0, 1.0, 1.0]
    assert by_uuid[shared.uuid]["grid"]["size"] == [400, 200]


def test_write_replaces_the_file_and_leaves_no_temporary(tmp_path):
    path = tmp_path / "sub" / "obstacles.yaml"
    snapshot.write_atomically(str(path), "a: 1\n")
    snapshot.write_atomically(str(path), "a: 2\n")
    assert path.read_text() == "a: 2\n"
    assert os.listdir(str(path.parent)) == ["obstacles.yaml"]


def test_failed_write_keeps_the_old_file_and_no_temporary(tmp_path):
    path = tmp_path / "obstacles.yaml"
    snapshot.write_atomically(str(path), "a: 1\n")

    class Unwritable:
        def __str__(self):
            raise RuntimeError("boom")

    with pytest.raises(TypeError):
        snapshot.write_atomically(str(path), Unwritable())
    assert path.read_text() == "a: 1\n"
    assert os.listdir(str(tmp_path)) == ["obstacles.yaml"]
