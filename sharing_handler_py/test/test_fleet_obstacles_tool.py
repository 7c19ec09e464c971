"""rosrun sharing_handler_py fleet_obstacles: bad arguments are refused before it talks to ROS."""
import os
import subprocess
import sys

import pytest

TOOL = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scripts", "fleet_obstacles")


@pytest.mark.parametrize("args, says", [
    (["remove", "some-uuid"], "remove needs --by NAME"),
    (["remove", "--by", "anna"], "remove needs a uuid or --rect"),
    (["remove", "u", "--rect", "0", "0", "1", "1", "--by", "anna"], "remove needs a uuid or --rect"),
    (["forget"], "invalid choice"),
])
def test_bad_arguments_are_refused_with_the_reason(args, says):
    proc = subprocess.run([sys.executable, TOOL] + args, capture_output=True, text=True, timeout=30,
                          env=dict(os.environ, ROS_MASTER_URI="http://127.0.0.1:1"))
    assert proc.returncode == 2
    assert says in proc.stderr

