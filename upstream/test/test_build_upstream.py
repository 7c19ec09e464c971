"""upstream/build_upstream.py: the pinned list, the sources, the cache, and what it says when
something is missing. No build runs here (make setup does that); the program is run as make setup
runs it where it must fail early: sources missing with no network, an archive corrupted."""
import hashlib
import io
import json
import os
import subprocess
import sys
import tarfile
import time

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
UPSTREAM = os.path.dirname(HERE)
sys.path.insert(0, UPSTREAM)
import build_upstream as bu  # noqa: E402

SHA = "a" * 64
COMMIT = "b" * 40


def pin_line(name="angles", build="catkin", archive="angles-1.tar.gz", sha=SHA, repo="https://example.org/angles",
             commit=COMMIT):
    return " ".join((name, build, archive, sha, repo, commit))


def write(path, text):
    with open(path, "w") as f:
        f.write(text)
    return str(path)


def make_archive(path, entries):
    """A .tar.gz with the given {name: bytes} files."""
    with tarfile.open(path, "w:gz") as tar:
        for name, data in entries.items():
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tar.addfile(info, io.BytesIO(data))
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()


# --- the pinned list ---------------------------------------------------------------------------

def test_the_repositorys_pins_read_and_name_every_source_the_real_stack_needs():
    pins = bu.read_pins()
    assert {p.name for p in pins} == {"Stage", "angles", "class_loader", "pluginlib", "dynamic_reconfigure",
                                      "navigation", "stage_ros"}
    assert [p.name for p in pins if p.build == "cmake"] == ["Stage"]


@pytest.mark.parametrize("line, words", [
    (pin_line(sha="a" * 63), "sha256"),
    (pin_line(sha="g" * 64), "sha256"),
    (pin_line(commit="b" * 39), "commit"),
    (pin_line(build="make"), "neither catkin nor cmake"),
    (pin_line(repo="http://example.org/x"), "https URL"),
    (pin_line(archive="../x.tar.gz"), "archive"),
    (pin_line(name="bad/name"), "name"),
    (pin_line() + " extra", "7 fields, expected 6"),
])
def test_a_bad_pins_line_is_refused_with_its_number_and_what_is_wrong(tmp_path, line, words):
    path = write(tmp_path / "pins.txt", "# comment\n\n" + line + "\n")
    with pytest.raises(bu.UpstreamError) as err:
        bu.read_pins(path)
    assert "pins line 3" in str(err.value) and words in str(err.value)


def test_pins_with_a_name_twice_or_none_at_all_are_refused(tmp_path):
    with pytest.raises(bu.UpstreamError, match="twice"):
        bu.read_pins(write(tmp_path / "p", pin_line() + "\n" + pin_line() + "\n"))
    with pytest.raises(bu.UpstreamError, match="no pins"):
        bu.read_pins(write(tmp_path / "q", "# only a comment\n"))
    with pytest.raises(bu.UpstreamError, match="cannot read"):
        bu.read_pins(str(tmp_path / "absent"))


def test_every_patch_names_a_pinned_source_and_says_why_before_its_diff():
    names = {p.name for p in bu.read_pins()}
    patches = sorted(os.listdir(bu.PATCH_DIR))
    assert patches, "no patches: stage_ros needs two on Debian 12"
    for patch in patches:
        assert patch.split("-", 1)[0] in names, patch
        with open(os.path.join(bu.PATCH_DIR, patch)) as f:
            text = f.read()
        why = text[:text.index("\n--- ")]
        assert len(why.split()) >= 20, "%s: no comment saying why before the diff" % patch


def test_the_cache_key_changes_with_a_pin_or_a_patch_and_not_otherwise(tmp_path):
    pins = write(tmp_path / "pins.txt", pin_line() + "\n")
    patches = tmp_path / "patches"
    patches.mkdir()
    write(patches / "angles-01-x.patch", "why\n--- a/x\n+++ b/x\n")
    key = bu.cache_key(pins, str(patches))
    assert key == bu.cache_key(pins, str(patches))
    write(patches / "angles-01-x.patch", "why, said better\n--- a/x\n+++ b/x\n")
    assert bu.cache_key(pins, str(patches)) != key
    key = bu.cache_key(pins, str(patches))
    write(pins, pin_line(commit="c" * 40) + "\n")
    assert bu.cache_key(pins, str(patches)) != key


# --- sources -----------------------------------------------------------------------------------

def fake_pin(tmp_path, name="angles", entries=None, repo="https://invalid.invalid/angles"):
    folder = tmp_path / "archives"
    folder.mkdir(exist_ok=True)
    archive = "%s-1.tar.gz" % name
    sha = make_archive(str(folder / archive), entries or {"%s/package.xml" % name: b"<package/>"})
    return bu.Pin(name, "catkin", archive, sha, repo, COMMIT, line=1), str(folder)


def no_network(monkeypatch):
    """git's HTTP goes to a closed local port: a clone fails at once, as with no network."""
    monkeypatch.setenv("GIT_CONFIG_COUNT", "1")
    monkeypatch.setenv("GIT_CONFIG_KEY_0", "http.proxy")
    monkeypatch.setenv("GIT_CONFIG_VALUE_0", "http://127.0.0.1:9")


def test_an_archive_with_its_pinned_checksum_is_used(tmp_path):
    pin, folder = fake_pin(tmp_path)
    assert bu.locate_sources([pin], [folder], str(tmp_path / "clones")) == {
        "angles": ("archive", os.path.join(folder, pin.archive))}


def test_a_corrupted_archive_is_named_with_both_checksums_and_nothing_is_cloned(tmp_path, monkeypatch):
    pin, folder = fake_pin(tmp_path)
    with open(os.path.join(folder, pin.archive), "ab") as f:
        f.write(b"\0")
    monkeypatch.setattr(bu, "clone_pinned", lambda *a: pytest.fail("cloned although an archive was corrupt"))
    with pytest.raises(bu.UpstreamError) as err:
        bu.locate_sources([pin], [folder], str(tmp_path / "clones"))
    text = str(err.value)
    assert "checksum mismatch" in text and pin.archive in text and pin.sha256 in text


def test_an_absent_archive_with_no_network_names_it_and_the_two_ways_to_provide_it(tmp_path, monkeypatch):
    no_network(monkeypatch)
    pin, folder = fake_pin(tmp_path)
    os.remove(os.path.join(folder, pin.archive))
    started = time.monotonic()
    with pytest.raises(bu.UpstreamError) as err:
        bu.locate_sources([pin], [folder], str(tmp_path / "clones"))
    text = str(err.value)
    assert pin.archive in text and folder in text and "FLEET_UPSTREAM_SRC" in text and "github.com" in text
    assert "angles: " in text  # git's own reason
    assert time.monotonic() - started < 60  # generous: a refused connection fails in well under a second


def test_an_archive_that_would_unpack_outside_its_folder_is_refused(tmp_path):
    for entries in ({"angles/ok": b"", "other/x": b""}, {"angles/../../escape": b""}):
        pin, folder = fake_pin(tmp_path, entries=entries)
        with pytest.raises(bu.UpstreamError, match="outside the folder"):
            bu.unpack(pin, ("archive", os.path.join(folder, pin.archive)), str(tmp_path / "out"))


def test_a_patch_that_does_not_apply_is_named(tmp_path):
    pin, folder = fake_pin(tmp_path, entries={"angles/a.txt": b"one\n"})
    tree = bu.unpack(pin, ("archive", os.path.join(folder, pin.archive)), str(tmp_path / "src"))
    patches = tmp_path / "patches"
    patches.mkdir()
    write(patches / "angles-01-fix.patch", "why\n--- a/a.txt\n+++ b/a.txt\n@@ -1 +1 @@\n-two\n+three\n")
    with pytest.raises(bu.UpstreamError, match="angles-01-fix.patch does not apply"):
        bu.apply_patches(pin, tree, str(patches))
    write(patches / "angles-01-fix.patch", "why\n--- a/a.txt\n+++ b/a.txt\n@@ -1 +1 @@\n-one\n+three\n")
    bu.apply_patches(pin, tree, str(patches))
    with open(os.path.join(tree, "a.txt")) as f:
        assert f.read() == "three\n"


# --- the cache ---------------------------------------------------------------------------------

def fill(build_dir, files=bu.EXPECTED_FILES, complete=True):
    for rel in files:
        path = os.path.join(build_dir, rel)
        os.makedirs(os.path.dirname(path), exist_ok=True)
        open(path, "w").close()
    if complete:
        write(os.path.join(build_dir, "COMPLETE"), json.dumps({"key": "k"}))


def test_only_a_complete_and_whole_build_counts_as_built(tmp_path):
    cache, key = str(tmp_path), "0123456789abcdef"
    build_dir = os.path.join(cache, key)
    assert bu.complete_build(cache, key) is None
    fill(build_dir, complete=False)  # stopped after the last program, before COMPLETE
    assert bu.complete_build(cache, key) is None
    fill(build_dir)
    assert bu.complete_build(cache, key) == build_dir
    os.remove(os.path.join(build_dir, "devel_isolated/stage_ros/lib/stage_ros/stageros"))  # half deleted
    assert bu.complete_build(cache, key) is None


def clean_env(tmp_path, **extra):
    env = {k: v for k, v in os.environ.items() if k not in ("ROS_PACKAGE_PATH", "CMAKE_PREFIX_PATH")}
    env.update(FLEET_UPSTREAM_CACHE=str(tmp_path / "cache"), GIT_CONFIG_COUNT="1",
               GIT_CONFIG_KEY_0="http.proxy", GIT_CONFIG_VALUE_0="http://127.0.0.1:9", **extra)
    return env


def run_setup_step(env):
    started = time.monotonic()
    proc = subprocess.run([sys.executable, os.path.join(UPSTREAM, "build_upstream.py")], env=env,
                          capture_output=True, text=True, timeout=300)
    return proc, time.monotonic() - started


def test_setup_with_the_archives_moved_away_and_no_network_fails_in_seconds_saying_what_and_how(tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    proc, seconds = run_setup_step(clean_env(tmp_path, FLEET_UPSTREAM_SRC=str(empty)))
    assert proc.returncode == 1, proc.stdout + proc.stderr
    for pin in bu.read_pins():
        assert pin.archive in proc.stderr
    assert "FLEET_UPSTREAM_SRC" in proc.stderr and "github.com" in proc.stderr
    assert "Traceback" not in proc.stderr
    assert seconds < 60, "took %.0f s" % seconds
    assert not bu.complete_build(str(tmp_path / "cache"), bu.cache_key())


def test_setup_with_a_corrupted_archive_names_the_checksum_mismatch(tmp_path):
    folder = tmp_path / "archives"
    folder.mkdir()
    for pin in bu.read_pins():
        write(folder / pin.archive, "not the archive")
    proc, _ = run_setup_step(clean_env(tmp_path, FLEET_UPSTREAM_SRC=str(folder)))
    assert proc.returncode == 1
    assert "checksum mismatch" in proc.stderr and "navigation-" in proc.stderr and "Traceback" not in proc.stderr


def test_a_cached_complete_build_is_reused_without_building(tmp_path):
    env = clean_env(tmp_path, FLEET_UPSTREAM_SRC=str(tmp_path / "nothing-here"))
    fill(os.path.join(str(tmp_path / "cache"), bu.cache_key()))
    proc, seconds = run_setup_step(env)
    assert proc.returncode == 0, proc.stderr
    assert "built before" in proc.stdout
    assert os.readlink(str(tmp_path / "cache" / "current")) == bu.cache_key()


def test_a_new_build_keeps_the_one_it_replaces_and_removes_older_ones(tmp_path):
    cache = str(tmp_path)
    for key in ("a" * 16, "b" * 16, "c" * 16):
        fill(os.path.join(cache, key))
    bu.point_current(cache, "b" * 16)
    previous = bu.current_key(cache)
    bu.point_current(cache, "c" * 16)
    bu.remove_other_builds(cache, {"c" * 16, previous})
    assert sorted(n for n in os.listdir(cache) if n != "current") == ["b" * 16, "c" * 16]
    assert bu.current_key(cache) == "c" * 16
