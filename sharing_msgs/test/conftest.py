"""sharing_msgs' pure helpers are importable from src/ without a built workspace (appended, so a
sourced workspace's sharing_msgs, which also has the generated msg package, wins); ``ros_env``
is a private rosmaster on a free port for the tests that need real rospy."""
import os
import socket
import subprocess
import sys
import time

import pytest

SRC = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "src")
if SRC not in sys.path:
    sys.path.append(SRC)


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def ros_env():
    try:
        import rospy  # noqa: F401
        from sharing_msgs.msg import SharedObstacle  # noqa: F401
    except ImportError as err:
        pytest.skip("ROS workspace not built or not sourced (%s)" % err)
    port = _free_port()
    env = dict(os.environ, ROS_MASTER_URI="http://127.0.0.1:%d" % port, ROS_IP="127.0.0.1",
               ROS_HOSTNAME="127.0.0.1")
    master = subprocess.Popen(["rosmaster", "--core", "-p", str(port)], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 15
    while True:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
            break
        except OSError:
            assert time.monotonic() < deadline, "rosmaster did not start"
            time.sleep(0.05)
    yield env
    master.terminate()
    master.wait(10)
