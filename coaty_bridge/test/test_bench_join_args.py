"""bench_join refuses bad arguments with a clear message before it starts a broker or a robot."""
import os
import subprocess
import sys

import pytest

SCRIPT = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scripts", "bench_join")


@pytest.mark.parametrize("args, message", [
    (["--settle-timeout", "-1"], "--settle-timeout must be > 0, got -1.0"),
    (["--settle-timeout", "nan"], "--settle-timeout must be > 0, got nan"),
    (["--settle-timeout", "soon"], "invalid float value: 'soon'"),
    (["--robots", "0"], "--robots and --per-robot must be at least 1"),
])
def test_bad_arguments_are_refused_with_what_was_wrong(args, message):
    proc = subprocess.run([sys.executable, SCRIPT] + args, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert message in proc.stderr
    assert "bench_join:" in proc.stderr and "Traceback" not in proc.stderr
