"""fleet_launch's stage_world: the world Stage loads at another speed, and what it refuses."""
import importlib.machinery
import importlib.util
import os
import subprocess
import sys

import pytest

SCRIPT = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
                      "launch", "scripts", "stage_world")
WORLDS = os.path.join(os.path.dirname(SCRIPT), "..", "worlds")


def module():
    loader = importlib.machinery.SourceFileLoader("stage_world", SCRIPT)
    spec = importlib.util.spec_from_loader("stage_world", loader)
    mod = importlib.util.module_from_spec(spec)
    loader.exec_module(mod)
    return mod


def test_the_copy_runs_at_the_speed_asked_beside_every_file_the_world_names(tmp_path):
    sw = module()
    copy = sw.world_at_speed(os.path.join(WORLDS, "corridors_2.world"), 2.5, str(tmp_path))
    with open(copy) as f:
        text = f.read()
    assert text.splitlines()[-1] == "speedup 2.5"
    assert 'include "corridors.inc"' in text
    # Stage resolves the include and the bitmap it names relative to the world it loads
    assert os.path.isfile(os.path.join(str(tmp_path), "corridors.inc"))
    assert os.path.isfile(os.path.join(str(tmp_path), "corridors.pgm"))


@pytest.mark.parametrize("argv, words", [
    (["--speedup"], "needs a value"),
    (["--speedup", "fast", "a.world"], "must be a number"),
    (["--speedup", "0", "a.world"], "must be > 0"),
    (["--speedup", "-2", "a.world"], "must be > 0"),
    (["--speedup", "nan", "a.world"], "must be > 0"),
    (["-u"], "one .world file"),
    (["a.world", "b.world"], "one .world file"),
])
def test_bad_arguments_are_refused_saying_what_is_wrong(argv, words):
    with pytest.raises(ValueError, match=words):
        module().parse(argv)


def test_a_missing_world_file_is_named_and_nothing_starts(tmp_path):
    proc = subprocess.run([sys.executable, SCRIPT, "--speedup", "2", "-u", str(tmp_path / "none.world")],
                          capture_output=True, text=True, timeout=30)
    assert proc.returncode == 2 and "none.world: no such world file" in proc.stderr


def test_speed_one_and_rosrun_arguments_pass_through():
    speedup, args = module().parse(["-u", "w.world", "__name:=stageros", "__log:=/x.log"])
    assert speedup == 1.0 and args == ["-u", "w.world", "__name:=stageros", "__log:=/x.log"]
