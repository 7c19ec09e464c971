"""A clone of the repository alone is complete: the reference data the tests, benchmarks and launch files
read is in data/ (sources and licences in data/README.md), and nothing reads a folder beside the
repository, except the upstream build's pinned source archives (upstream/README.md)."""
import glob
import os
import re
import subprocess

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
DATA = os.path.join(ROOT, "data")
# What may name a folder beside the repository: the upstream build's source archives.
ALLOWED = {"upstream/build_upstream.py", "upstream/pins.txt", "upstream/README.md",
           "scripts/test/test_docs.py"}   # its own self-check names such references on purpose
SOURCES = ("*.py", "*.launch", "*.test", "*.sh", "*.cpp", "*.h", "*.yaml", "*.md", "*.world", "*.inc")
BESIDE = re.compile(r"\.\./shared\b|\"shared\", \"data\"|'shared', 'data'|/work/shared")


def tracked(*patterns):
    out = subprocess.run(["git", "-C", ROOT, "ls-files", "--"] + list(patterns) + ["*/bench_*", "*/scripts/*"],
                         capture_output=True, text=True, check=True).stdout.split()
    return sorted(set(out))


def test_nothing_reads_a_folder_beside_the_repository():
    found = []
    for path in tracked(*SOURCES):
        if path in ALLOWED or path == "CHANGELOG.md" or path.startswith("scripts/test/test_data_in_repo"):
            continue
        full = os.path.join(ROOT, path)
        if not os.path.isfile(full):
            continue
        with open(full, encoding="utf-8", errors="replace") as handle:
            for number, line in enumerate(handle, 1):
                if BESIDE.search(line):
                    found.append("%s:%d: %s" % (path, number, line.strip()[:100]))
    assert not found, "reads data from beside the repository (keep it in data/):\n" + "\n".join(found)


def env_data(**env):
    base = {k: v for k, v in os.environ.items() if k != "FLEET_SHARED_DATA"}
    base.update(env)
    out = subprocess.run(["bash", "-c", "source scripts/env.sh >/dev/null 2>&1; echo \"$FLEET_SHARED_DATA\""],
                         cwd=ROOT, env=base, capture_output=True, text=True, check=True).stdout.strip()
    return out


def test_env_points_at_the_repository_data_unless_told_otherwise(tmp_path):
    assert env_data() == DATA
    assert env_data(FLEET_SHARED_DATA=str(tmp_path)) == str(tmp_path)


def test_every_data_file_is_tracked_and_described():
    readme = open(os.path.join(DATA, "README.md"), encoding="utf-8").read()
    files = [p for p in glob.glob(os.path.join(DATA, "**", "*"), recursive=True) if os.path.isfile(p)]
    assert files
    untracked = set(os.path.relpath(p, ROOT) for p in files) - set(tracked("data/*"))
    assert not untracked, "data files not in the repository: %s" % sorted(untracked)
    for path in files:
        rel = os.path.relpath(path, DATA)
        if rel == "README.md":
            continue
        # every file is named in the README, itself or by the folder it lies in
        named = [part for part in (rel, os.path.dirname(rel) + "/", rel.split("/")[0] + "/") if part in readme]
        assert named, "data/%s: not described in data/README.md (source, licence)" % rel


def test_the_willow_data_the_tests_read_is_there():
    for rel in ("stage_worlds/willow/willow-pr2-multi.world", "stage_worlds/maps/willow-full.pgm",
                "stage_worlds/stage_examples/simple.world", "move_base_config/costmap_common_params.yaml",
                "bags/willow_blocked_corridor_first_30s.bag", "bags/willow_recovery_178s_to_192s.bag"):
        assert os.path.isfile(os.path.join(DATA, rel)), rel
