"""map_server semantics of map_io and the map_server script's bad-file exit."""
import os
import subprocess

import numpy as np
import pytest
from PIL import Image

import sim_test_helpers as h
from fleet_sim.errors import MapError
from fleet_sim.map_io import load_map_args, load_map_image, load_map_yaml

SCRIPT = os.path.join(os.path.dirname(h.HERE), "scripts", "map_server")


def test_willow_map_as_the_tutorials_serve_it():
    m = load_map_image(h.WILLOW_PGM, 0.1)
    assert (m.width, m.height) == (584, 526)          # as in the recorded bag
    assert m.resolution == 0.1 and m.origin == (0.0, 0.0, 0.0)
    img = np.asarray(Image.open(h.WILLOW_PGM))
    # image row 0 is the top: it is the map's last row
    np.testing.assert_array_equal(m.data[-1] == 100, img[0] < 89.25)
    assert set(np.unique(m.data)) == {-1, 0, 100}
    assert m.data[np.flipud(img) == 205].tolist() == [-1] * int((img == 205).sum())   # 205 = unknown
    assert (m.data[np.flipud(img) == 254] == 0).all()


def _png(tmp_path, pixels, name="m.png"):
    path = tmp_path / name
    Image.fromarray(np.array(pixels, dtype=np.uint8)).save(path)
    return str(path)


def test_thresholds_negate_and_modes(tmp_path):
    # values: black, 89 (occ 0.651), 90 (occ 0.647), 205 (occ 0.196..), 206, white
    img = _png(tmp_path, [[0, 89, 90, 205, 206, 255]])
    assert load_map_image(img, 0.05).data.tolist() == [[100, 100, -1, -1, 0, 0]]
    assert load_map_image(img, 0.05, negate=True).data.tolist() == [[0, -1, -1, 100, 100, 100]]
    scale = load_map_image(img, 0.05, mode="scale").data.tolist()[0]
    assert scale[:2] == [100, 100] and scale[4:] == [0, 0] and 0 < scale[2] < 100
    assert load_map_image(img, 0.05, occupied_thresh=0.5).data.tolist() == [[100, 100, 100, -1, 0, 0]]


def test_yaml_with_origin(tmp_path):
    img = _png(tmp_path, [[0, 255], [255, 255]])
    y = tmp_path / "m.yaml"
    y.write_text("image: m.png\nresolution: 0.5\norigin: [-1.0, 2.0, 0.0]\nnegate: 0\n"
                 "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
    m = load_map_yaml(str(y))
    assert m.origin == (-1.0, 2.0, 0.0) and m.resolution == 0.5
    assert m.data.tolist() == [[0, 0], [100, 0]]      # top-left pixel lands in the last row
    assert load_map_args([str(y)]).data.tolist() == m.data.tolist()
    assert load_map_args([img, "0.5"]).origin == (0.0, 0.0, 0.0)


@pytest.mark.parametrize("content, message", [
    ("image: m.png\nresolution: 0.5\n", "has no 'origin'"),
    ("image: nope.png\nresolution: 0.5\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n",
     "nope.png not found"),
    ("image: m.png\nresolution: -1\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n",
     "resolution must be > 0"),
    ("image: m.png\nresolution: 0.1\norigin: [0, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n",
     "origin must be [x, y, yaw]"),
    ("image: m.png\nresolution: 0.1\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.1\nfree_thresh: 0.196\n",
     "free_thresh < occupied_thresh"),
    ("image: [unclosed\n", "not valid YAML"),
    ("just text\n", "must be a mapping"),
])
def test_bad_yaml_files(tmp_path, content, message):
    _png(tmp_path, [[0, 255]])
    y = tmp_path / "bad.yaml"
    y.write_text(content)
    with pytest.raises(MapError) as info:
        load_map_yaml(str(y))
    assert message in str(info.value)
    assert "bad.yaml" in str(info.value) or "nope.png" in str(info.value) or "m.png" in str(info.value)


def test_unreadable_image(tmp_path):
    bad = tmp_path / "garbage.pgm"
    bad.write_bytes(b"P5\n12 nonsense")
    with pytest.raises(MapError, match="garbage.pgm cannot be read"):
        load_map_image(str(bad), 0.1)
    with pytest.raises(MapError, match="resolution must be a number"):
        load_map_image(h.WILLOW_PGM, "fast")


@pytest.mark.parametrize("args, message", [
    (["/nonexistent/map.pgm", "0.1"], "map image /nonexistent/map.pgm not found"),
    (["/nonexistent/map.yaml"], "cannot be read"),
    ([], "usage: map_server"),
])
def test_map_server_script_exits_non_zero_on_bad_input(args, message):
    env = dict(os.environ, PYTHONPATH=os.path.join(os.path.dirname(h.HERE), "src") + os.pathsep
               + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.run(["/usr/bin/python3", SCRIPT] + args, capture_output=True, text=True,
                          timeout=30, env=env)
    assert proc.returncode == 1
    assert message in proc.stderr
