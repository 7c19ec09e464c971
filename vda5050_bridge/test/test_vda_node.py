"""The rospy node through a private rosmaster and a private mosquitto: the handler's obstacle list
(published here) turns into the blocked edge in the state master control reads over MQTT, and goes
after the clear; a 3.0 zone master control enables comes out on from_fleet as an obstacle with
source master_control and the map's cells inside the zone, and as an update clearing them all when
the zone set is deleted; with the real SharingHandler the zone enters its obstacle list (source
master_control) and leaves it."""
import os
import signal
import socket
import subprocess
import sys
import threading
import time

import pytest

from vda5050_bridge import core, schemas
from test_vda_core import MAN, actions_doc, order_doc, zone_set_doc
from test_vda_mqtt import Master

pytestmark = pytest.mark.broker
PKG = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _ros_missing():
    try:
        import rospy  # noqa: F401
        from sharing_msgs.msg import SharedObstacle  # noqa: F401
    except ImportError as err:
        return "ROS workspace not built or not sourced (%s)" % err
    return None


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _start_master(ros_port, log_dir):
    """(env, process): a private rosmaster on ``ros_port`` and the environment that points a node at it, with this
    package's source first on PYTHONPATH."""
    env = dict(os.environ, ROS_MASTER_URI="http://127.0.0.1:%d" % ros_port, ROS_IP="127.0.0.1",
               ROS_HOSTNAME="127.0.0.1", PYTHONPATH=os.path.join(PKG, "src") + os.pathsep + os.environ.get("PYTHONPATH", ""),
               ROS_LOG_DIR=log_dir)
    return env, subprocess.Popen(["rosmaster", "--core", "-p", str(ros_port)], env=env,
                                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def _stop(proc):
    """SIGINT as roslaunch sends it, SIGKILL if the process has not ended 10 s later."""
    if proc is not None and proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def test_node_reports_blocked_edge_and_delivers_zone(broker, wait_for):
    reason = _ros_missing()
    if reason:
        pytest.skip(reason)
    import rospy
    from nav_msgs.msg import OccupancyGrid
    from sharing_msgs.msg import SharedObstacle, SharedObstacleArray

    host, port = broker
    ros_port = _free_port()
    env, master_proc = _start_master(ros_port, os.environ.get("ROS_LOG_DIR", "/tmp/vda5050_bridge_test_logs"))
    node = None
    mc = None
    procs = []
    try:
        wait_for(lambda: _connects(ros_port), what="rosmaster")
        os.environ.update(ROS_MASTER_URI=env["ROS_MASTER_URI"], ROS_IP="127.0.0.1", ROS_HOSTNAME="127.0.0.1")
        node = subprocess.Popen([sys.executable, os.path.join(PKG, "scripts", "vda5050_bridge"), "__ns:=robot_0",
                                 "__name:=vda5050_bridge", "_protocol_version:=3.0.0", "_manufacturer:=" + MAN,
                                 "_broker_port:=%d" % port, "_state_interval:=30.0"],
                                env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        rospy.init_node("vda_test", anonymous=True, disable_signals=True)
        got = []
        lock = threading.Lock()

        def on_fleet(msg):
            with lock:
                got.append(msg)
        rospy.Subscriber("/robot_0/from_fleet", SharedObstacle, on_fleet)
        lists = rospy.Publisher("/robot_0/shared_obstacle_list", SharedObstacleArray, queue_size=1, latch=True)
        maps = rospy.Publisher("/map", OccupancyGrid, queue_size=1, latch=True)
        grid = OccupancyGrid()
        grid.header.frame_id = "map"
        grid.info.resolution, grid.info.width, grid.info.height = 0.5, 40, 40
        grid.info.origin.position.x = grid.info.origin.position.y = -10.0
        grid.info.origin.orientation.w = 1.0
        grid.data = [0] * 1600
        maps.publish(grid)

        mc = Master(host, port, core.topic_prefix("uagv", "3.0.0", MAN, "robot_0"))
        assert mc.ready.wait(10)
        wait_for(lambda: mc.last_state() is not None, timeout=30, what="first state from the node")
        mc.send("order", order_doc("3.0.0"))
        wait_for(lambda: mc.last_state()["orderId"] == "order-1", what="order in state")

        def publish_list(*rects):
            array = SharedObstacleArray()
            for i, rect in enumerate(rects):
                array.obstacles.append(SharedObstacle(uuid="u-%d" % i, source="robot_1", rectangle_shape=list(rect)))
            lists.publish(array)
        publish_list((1.5, -0.2, 2.0, 0.2))
        wait_for(lambda: mc.last_state()["errors"], what="blocked edge in the node's state")
        assert mc.last_state()["errors"][0]["errorReferences"][0] == {"referenceKey": "edgeId", "referenceValue": "e1"}
        publish_list()
        wait_for(lambda: mc.last_state()["errors"] == [], what="error withdrawn after the clear")

        mc.send("zoneSet", zone_set_doc("zs-1"))
        mc.send("instantActions", actions_doc("3.0.0", ("enableZoneSet", {"zoneSetId": "zs-1"})))
        wait_for(lambda: len(got) == 1, what="zone as an obstacle on from_fleet")
        first = got[0]
        assert first.source == "master_control" and first.version == 1 and first.uuid == core.area_uuid("zs-1/z-blocked")
        # zone x 1..2, y -1..1 on a 0.5 m grid from -10: cell centres 1.25, 1.75 x -0.75..0.75
        assert sorted(first.marked_indexes) == sorted(y * 40 + x for x in (22, 23) for y in (18, 19, 20, 21))
        assert list(first.rectangle_shape) == [1.0, -1.0, 2.0, 1.0]
        mc.send("instantActions", actions_doc("3.0.0", ("deleteZoneSet", {"zoneSetId": "zs-1"})))
        wait_for(lambda: len(got) == 2, what="zone withdrawn on from_fleet")
        assert got[1].uuid == first.uuid and got[1].version == 2 and not got[1].marked_indexes
        assert sorted(got[1].cleared_indexes) == sorted(first.marked_indexes)
        for doc in mc.states():
            assert not schemas.errors("3.0.0", "state", doc)

        # The same through the real SharingHandler: the zone is in its obstacle list (what the
        # layer draws into the global costmap) with source master_control, and leaves with it.
        lists.unregister()
        handler = subprocess.Popen(["rosrun", "sharing_handler_py", "sharing_handler", "__ns:=robot_0",
                                    "__name:=sharing_handler"], env=env, stdout=subprocess.DEVNULL,
                                   stderr=subprocess.DEVNULL)
        procs.append(handler)
        held = {}

        def on_list(array):
            with lock:
                held.clear()
                held.update({o.uuid: o for o in array.obstacles})
        rospy.Subscriber("/robot_0/shared_obstacle_list", SharedObstacleArray, on_list)
        wait_for(lambda: rospy.get_published_topics() and any(
            t == "/robot_0/shared_obstacle_list" for t, _ in rospy.get_published_topics()), timeout=30,
            what="handler up")
        wait_for(lambda: _subscribed(rospy, "/robot_0/from_fleet", "/robot_0/sharing_handler"), timeout=30,
                 what="handler subscribed to from_fleet")
        mc.send("zoneSet", zone_set_doc("zs-2"))
        mc.send("instantActions", actions_doc("3.0.0", ("enableZoneSet", {"zoneSetId": "zs-2"})))
        uuid2 = core.area_uuid("zs-2/z-blocked")
        wait_for(lambda: uuid2 in held, timeout=30, what="zone in the handler's obstacle list")
        assert held[uuid2].source == "master_control"
        assert sorted(held[uuid2].marked_indexes) == sorted(first.marked_indexes)
        mc.send("instantActions", actions_doc("3.0.0", ("deleteZoneSet", {"zoneSetId": "zs-2"})))
        wait_for(lambda: uuid2 not in held, timeout=30, what="zone gone from the handler's list")
    finally:
        if mc is not None:
            mc.stop()
        for proc in procs:
            _stop(proc)
        _stop(node)
        master_proc.terminate()
        master_proc.wait(10)


def _subscribed(rospy, topic, node_name):
    _code, _msg, (_pubs, subs, _srvs) = rospy.get_master().getSystemState()
    return any(t == topic and node_name in names for t, names in subs)


def _connects(port):
    try:
        socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
        return True
    except OSError:
        return False


def test_node_as_the_readme_shows_it_warns_about_namespace_handler_and_broker(tmp_path, wait_for):
    """`rosrun vda5050_bridge vda5050_bridge` with no namespace, no handler and no broker: before, one info
    line and silence. Now three warnings say what is wrong and what to do (the broker's and the list's
    repeat while it lasts)."""
    reason = _ros_missing()
    if reason:
        pytest.skip(reason)
    ros_port, dead_port = _free_port(), _free_port()      # nothing listens on dead_port
    env, master_proc = _start_master(ros_port, str(tmp_path / "log"))
    log = tmp_path / "node.err"
    node = None
    try:
        wait_for(lambda: _connects(ros_port), what="rosmaster")
        with open(str(log), "w") as err:
            node = subprocess.Popen([sys.executable, os.path.join(PKG, "scripts", "vda5050_bridge"),
                                     "_broker_port:=%d" % dead_port], env=env, stdout=subprocess.DEVNULL, stderr=err)

        def said(text):
            return text in log.read_text()
        wait_for(lambda: said("runs in the root namespace as robot 'robot'"), timeout=30, what="namespace warning")
        wait_for(lambda: said("VDA 5050 broker 127.0.0.1:%d not reachable" % dead_port), timeout=30,
                 what="broker warning")
        wait_for(lambda: said("nothing publishes /shared_obstacle_list"), timeout=30, what="handler list warning")
        assert "ROS_NAMESPACE=robot_0 rosrun vda5050_bridge vda5050_bridge" in log.read_text()
        assert node.poll() is None, "the node keeps running"
    finally:
        _stop(node)
        master_proc.terminate()
        master_proc.wait(10)


def test_in_a_namespace_with_a_handler_list_and_a_broker_it_stays_quiet(broker, tmp_path, wait_for):
    """The other side of the warnings above: set up as documented, none of them comes (judged after eight
    state heartbeats at 1 s, past the first warnings' 5 s)."""
    reason = _ros_missing()
    if reason:
        pytest.skip(reason)
    host, port = broker
    ros_port = _free_port()
    env, master_proc = _start_master(ros_port, str(tmp_path / "log"))
    log = tmp_path / "node.err"
    procs = []
    mc = None
    try:
        wait_for(lambda: _connects(ros_port), what="rosmaster")
        # the handler's latched list, as a sharing_handler in robot_0 publishes it
        procs.append(subprocess.Popen(["rostopic", "pub", "-l", "/robot_0/shared_obstacle_list",
                                       "sharing_msgs/SharedObstacleArray", "{}"], env=env,
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        mc = Master(host, port, core.topic_prefix("uagv", "2.1.0", "fleet", "robot_0"))
        assert mc.ready.wait(10)
        with open(str(log), "w") as err:
            procs.append(subprocess.Popen([sys.executable, os.path.join(PKG, "scripts", "vda5050_bridge"),
                                           "__ns:=robot_0", "__name:=vda5050_bridge", "_broker_port:=%d" % port,
                                           "_state_interval:=1.0"], env=env, stdout=subprocess.DEVNULL, stderr=err))
        wait_for(lambda: len(mc.states()) >= 8, timeout=60, what="eight states from the node")
        text = log.read_text()
        assert "root namespace" not in text and "not reachable" not in text and "nothing publishes" not in text, text
    finally:
        if mc is not None:
            mc.stop()
        for proc in procs:
            _stop(proc)
        master_proc.terminate()
        master_proc.wait(10)
