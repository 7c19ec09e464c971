"""The fleet and lifecycle benches, started from a shell that has not sourced scripts/env.sh, say so and what to do
in one line, with a non-zero exit, instead of ending in an import or rospkg traceback."""
import os
import subprocess
import sys

import pytest

SCRIPTS = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scripts")


@pytest.mark.parametrize("script, args", [("bench_fleet", ["--robots", "2"]), ("bench_lifecycle", ["--delays", "10"])])
def test_a_bench_without_the_workspace_says_to_source_env_sh(script, args):
    bare = {"PATH": "/usr/bin:/bin", "HOME": os.environ.get("HOME", "/tmp")}
    out = subprocess.run([sys.executable, os.path.join(SCRIPTS, script)] + args, env=bare,
                         capture_output=True, text=True, timeout=60)
    assert out.returncode != 0
    assert "Traceback" not in out.stderr, out.stderr
    assert out.stderr.startswith(script + ": ") and "source scripts/env.sh" in out.stderr, out.stderr


def test_a_bench_that_finds_our_modules_but_not_fleet_launch_says_so():
    """fleet_tests importable (PYTHONPATH) but no ROS package path: fleet_launch_path names the package."""
    bare = {"PATH": "/usr/bin:/bin", "HOME": os.environ.get("HOME", "/tmp"),
            "PYTHONPATH": os.path.join(os.path.dirname(SCRIPTS), "src")}
    out = subprocess.run([sys.executable, os.path.join(SCRIPTS, "bench_lifecycle"), "--delays", "10"], env=bare,
                         capture_output=True, text=True, timeout=60)
    assert out.returncode != 0
    assert "Traceback" not in out.stderr, out.stderr
    assert out.stderr.startswith("bench_lifecycle: package fleet_launch not found: ") \
        and "source scripts/env.sh" in out.stderr, out.stderr
