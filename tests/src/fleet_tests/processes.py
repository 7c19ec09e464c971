"""Stopping a child process the way ROS tools expect: a signal it shuts down on (SIGINT for roslaunch,
rviz and rospy nodes), then SIGKILL to its process group if it has not gone within `timeout` s."""
import os
import signal
import subprocess


def stop(proc, first=signal.SIGINT, timeout=15.0):
    """Stops proc (started with start_new_session=True, so its group is its own); a no-op if it ended."""
    if proc is None or proc.poll() is not None:
        return
    proc.send_signal(first)
    try:
        proc.wait(timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
