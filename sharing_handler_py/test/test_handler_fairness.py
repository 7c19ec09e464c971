"""Fair delivery in the handler node (issue 43, item 5): a login flooding distinct, valid obstacles fills only its
own queue, and another robot's message is applied after at most one of the flood's, not after the flood's tail.

Through the node's own path (``_queue_fleet``, what rospy's from_fleet thread calls, and ``serve_one``, the worker's
step) on a real SharingHandler, served step by step: ordering, no timing. Every flood message is a new obstacle
far from the others (none merges, none is a repeat, all within the quotas), so each must be applied: a handler that
served fleet messages in arrival order applies the honest one last (red with the queue keyed on anything but the
source)."""
import threading

import pytest

rospy = pytest.importorskip("rospy")
pytest.importorskip("sharing_msgs.msg")

from handler_fixtures import GRID, Recorder, U, rect, update  # noqa: E402
from sharing_handler_py.node import HandlerNode, msg_from_obstacle  # noqa: E402
from sharing_msgs.authority import FairQueue  # noqa: E402

FLOOD = 150


def far(k, source):
    """A one-cell obstacle in slot k: slots are 1 m apart (beyond merge_distance 0.5 m), so none merge; robot_2's
    row lies 2 m beyond the flood's last."""
    col, row = (k % 20) * 20, (k // 20) * 20 + (180 if source == "robot_2" else 0)
    x, y = GRID.origin_x + col * GRID.resolution, GRID.origin_y + row * GRID.resolution
    return update(U("%s-%d" % (source[-1], k)), marked=(row * GRID.size_x + col,), version=1, source=source,
                  rectangle=rect(x, y, x + GRID.resolution, y + GRID.resolution), stamp=100.0)


def node_on(recorder):
    """The node's fleet path without ROS I/O: its queue, lock and handler (the parts _queue_fleet and serve_one use)."""
    node = HandlerNode.__new__(HandlerNode)
    node._lock = threading.RLock()
    node._fleet_inbox = FairQueue(10000)
    node.handler = recorder.handler
    return node


def test_a_flood_of_distinct_obstacles_does_not_hold_back_another_robots_message():
    recorder = Recorder(max_obstacles_per_source=FLOOD + 10, source_update_rate=1000.0, source_update_burst=FLOOD + 10)
    node = node_on(recorder)
    flood = [far(k, "robot_9") for k in range(FLOOD)]
    honest = far(0, "robot_2")
    for obstacle in flood:
        node._queue_fleet(msg_from_obstacle(obstacle), "from_fleet", True)
    node._queue_fleet(msg_from_obstacle(honest), "from_fleet", True)
    while node.serve_one(timeout=0):
        pass
    applied = [o.uuid for o in recorder.layer]
    assert len(applied) == FLOOD + 1, "every flood message is a new obstacle and must be applied"
    assert applied.index(honest.uuid) <= 1, "the honest robot's message waited for %d of the flood's" % (
        applied.index(honest.uuid))
    assert [u for u in applied if u != honest.uuid] == [o.uuid for o in flood], "the flood itself stays in order"
