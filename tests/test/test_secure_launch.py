"""Secure by default in the fleet launches (issue 27, item 9). fleet.launch and
move_base_fleet.launch give run_broker the robots and the credentials folder and no ~insecure, and
every bridge `authenticate_sources: true` and its own `password_file` (the parameters
coaty_bridge/test/test_secure_default.py runs its attacks with); insecure:=true turns all of it off.
And a running fleet.launch (2 robots, default arguments, its own master and ROS_HOME): an anonymous
peer and a wrong password are refused, neither robot_1's login nor another login can publish under
robot_0's sourceId, and a peer trying robot_0's client id does not cut robot_0 off."""
import os
import signal
import socket
import subprocess
import time
import uuid as uuidlib

import pytest
import yaml

ENV = dict(os.environ, ROS_IP="127.0.0.1", ROS_HOSTNAME="127.0.0.1")
REAL_STACK = ("stage_ros", "move_base", "navfn", "base_local_planner", "map_server", "fake_localization")
NS = "fleet"
OT = "org.fleetsharing.SharedObstacle"


def params(env, launch, *args):
    proc = subprocess.run(["roslaunch", "--dump-params", "fleet_launch", launch] + list(args),
                          capture_output=True, text=True, env=env, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return yaml.safe_load(proc.stdout)


def installed(name):
    return subprocess.run(["rospack", "find", name], capture_output=True, env=ENV).returncode == 0


@pytest.fixture(scope="module")
def stand_ins(tmp_path_factory):
    """move_base_fleet.launch needs the real stack's packages to be found (as test_move_base_launch.py)."""
    root = tmp_path_factory.mktemp("stand_ins")
    for name in REAL_STACK:
        if not installed(name):
            (root / name).mkdir()
            (root / name / "package.xml").write_text(
                '<?xml version="1.0"?>\n<package format="2"><name>%s</name><version>0.0.0</version>'
                '<description>stand-in</description><maintainer email="x@example.org">x</maintainer>'
                '<license>BSD</license><buildtool_depend>catkin</buildtool_depend></package>\n' % name)
    return dict(ENV, ROS_PACKAGE_PATH=str(root) + os.pathsep + ENV.get("ROS_PACKAGE_PATH", ""))


@pytest.mark.parametrize("launch", ["fleet.launch", "move_base_fleet.launch"])
def test_launch_runs_the_secure_default_and_insecure_opts_out(launch, stand_ins, tmp_path):
    env = dict(stand_ins, ROS_HOME=str(tmp_path / "ros_home"))
    folder = str(tmp_path / "ros_home" / "fleet_security")
    p = params(env, launch, "robots:=3")
    assert p["/fleet_broker/insecure"] is False
    assert p["/fleet_broker/robots"] == 3
    assert p["/fleet_broker/credentials_dir"] == folder
    for i in range(3):
        bridge = {k.rsplit("/", 1)[1]: v for k, v in p.items() if k.startswith("/robot_%d/coaty_bridge/" % i)}
        assert bridge["insecure"] is False and bridge["authenticate_sources"] is True
        assert bridge["password_file"] == "%s/robots/robot_%d.password" % (folder, i)
        assert bridge["broker_url_param"] == "/fleet/broker_url"
        # plausible evidence (issue 43), as coaty_bridge/test/test_secure_default.launch_bridge_params
        assert bridge["require_evidence"] is True and bridge["sensor_reach"] == bridge["max_sensor_reach"] == 4.0
        assert "password" not in bridge and "identity_id" not in bridge and "username" not in bridge
    p = params(env, launch, "robots:=2", "credentials:=/srv/fleet_secrets")
    assert p["/fleet_broker/credentials_dir"] == "/srv/fleet_secrets"
    assert p["/robot_1/coaty_bridge/password_file"] == "/srv/fleet_secrets/robots/robot_1.password"
    p = params(env, launch, "robots:=2", "insecure:=true")
    assert p["/fleet_broker/insecure"] is True
    for i in range(2):
        assert p["/robot_%d/coaty_bridge/insecure" % i] is True
        assert p["/robot_%d/coaty_bridge/authenticate_sources" % i] is False
        assert p["/robot_%d/coaty_bridge/require_evidence" % i] is False
        assert "/robot_%d/coaty_bridge/password_file" % i not in p


# ------------------------------------------------------------------ a running fleet.launch

def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_until(predicate, what, timeout=30.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = predicate()
        if value:
            return value
        time.sleep(0.05)
    raise AssertionError("timed out waiting for " + what)


class Peer:
    def __init__(self, port, username=None, password=None, client_id=None, subscribe="coaty/#"):
        from coaty_bridge.client import _make_paho_client
        self.accepted, self.refused, self.received = False, [], []
        self.done = False
        self.client = _make_paho_client(client_id or "peer-" + uuidlib.uuid4().hex[:10])
        self.client.reconnect_delay_set(60, 120)
        if username is not None:
            self.client.username_pw_set(username, password)
        self.subscribe = subscribe
        self.client.on_connect = self._on_connect
        self.client.on_subscribe = lambda *a: setattr(self, "done", True)
        self.client.on_message = lambda c, u, m: self.received.append(m.topic)
        self.client.connect_async("127.0.0.1", port)
        self.client.loop_start()
        wait_until(lambda: self.done or self.refused, "the broker's answer", timeout=15)

    def _on_connect(self, client, userdata, flags, rc, properties=None):
        if rc != 0:
            self.refused.append(rc)
            return
        self.accepted = True
        if self.subscribe:
            client.subscribe(self.subscribe)
        else:
            self.done = True

    def publish(self, topic, payload):
        self.client.publish(topic, payload).wait_for_publish(5)

    def close(self):
        self.client.disconnect()
        self.client.loop_stop()


def obstacle_event(source_id, source):
    from coaty_bridge import codec
    update = codec.ObstacleUpdate(str(uuidlib.uuid4()), source, 1, 10.0, "map", 60, (0.0, 0.0, 1.0, 1.0), 0.05,
                                  0.0, 0.0, 100, 100, (5, 6), ())
    return ("coaty/3/%s/ADV::%s/%s" % (NS, OT, source_id),
            codec.advertise_payload(codec.obstacle_to_object(update, OT)))


@pytest.fixture
def running_fleet(tmp_path):
    import rosgraph
    port = free_port()
    env = dict(ENV, ROS_MASTER_URI="http://127.0.0.1:%d" % port, ROS_HOME=str(tmp_path / "ros_home"))
    log = open(str(tmp_path / "launch.log"), "w")
    launch = subprocess.Popen(["roslaunch", "-p", str(port), "fleet_launch", "fleet.launch", "robots:=2"],
                              stdout=log, stderr=subprocess.STDOUT, env=env, start_new_session=True)
    os.environ["ROS_MASTER_URI"] = env["ROS_MASTER_URI"]
    master = rosgraph.Master("/test_secure_launch", master_uri=env["ROS_MASTER_URI"])

    def param(name):
        try:
            return master.getParam(name)
        except Exception:
            assert launch.poll() is None, open(str(tmp_path / "launch.log")).read()[-3000:]
            return None
    try:
        url = wait_until(lambda: param("/fleet/broker_url"), "/fleet/broker_url", timeout=60)
        monitor = param("/fleet/broker_monitor")
        yield int(url.rsplit(":", 1)[1]), monitor, str(tmp_path / "ros_home" / "fleet_security")
    finally:
        if launch.poll() is None:
            os.killpg(launch.pid, signal.SIGINT)
            try:
                launch.wait(30)
            except subprocess.TimeoutExpired:
                os.killpg(launch.pid, signal.SIGKILL)
                launch.wait()
        log.close()


def test_running_fleet_launch_refuses_anonymous_forged_sources_and_client_id_takeover(running_fleet):
    from coaty_bridge.identity import identity_for
    from coaty_bridge.security import read_password_file
    port, monitor, folder = running_fleet
    ids = {robot: identity_for(NS, robot) for robot in ("robot_0", "robot_1")}
    peers = []
    try:
        # (a) anonymous, and robot_0's login with a guessed password
        for kwargs in (dict(), dict(username=ids["robot_0"], password="guessed")):
            peer = Peer(port, **kwargs)
            peers.append(peer)
            assert peer.refused and not peer.accepted, "the fleet's broker accepted %r" % (kwargs,)
        assert monitor and monitor["username"] == "fleet_monitor"
        watcher = Peer(port, monitor["username"], read_password_file(monitor["password_file"]))
        peers.append(watcher)
        assert watcher.accepted

        def heartbeats(robot):
            # its 1 s echoes (namespace <NS>.echo, which the ACL must let it write) and its peer heartbeats
            return [t for t in list(watcher.received) if t.startswith(("coaty/3/%s/CHN:" % NS, "coaty/3/%s.echo/CHN:" % NS))
                    and t.endswith(ids[robot])]
        for robot in ids:
            wait_until(lambda r=robot: heartbeats(r), robot + "'s heartbeats (its bridge logged in)", timeout=60)
        # (b) a compromised robot_1 (its own login) and the monitor login publish under robot_0's sourceId
        robot_1 = Peer(port, ids["robot_1"], read_password_file(folder + "/robots/robot_1.password"), subscribe=None)
        peers.append(robot_1)
        assert robot_1.accepted
        forged_topic, forged = obstacle_event(ids["robot_0"], "robot_0")
        own_topic, own = obstacle_event(ids["robot_1"], "robot_1")
        robot_1.publish(forged_topic, forged)
        watcher.publish(forged_topic, forged)
        robot_1.publish(own_topic, own)
        wait_until(lambda: own_topic in watcher.received, "robot_1's own event")
        time.sleep(0.3)
        assert forged_topic not in watcher.received, "an event under robot_0's sourceId got through"
        robot_1.close()
        # (c) robot_0's login as client id, without its password
        deadverts = "coaty/3/%s/DAD/%s" % (NS, ids["robot_0"])
        before = len(heartbeats("robot_0"))
        for kwargs in (dict(client_id=ids["robot_0"]), dict(client_id=ids["robot_0"], username=ids["robot_0"],
                                                            password="guessed")):
            peer = Peer(port, **kwargs)
            peers.append(peer)
            assert not peer.accepted
        time.sleep(2.5)
        assert deadverts not in watcher.received, "robot_0 was cut off"
        assert len(heartbeats("robot_0")) > before, "robot_0's heartbeats stopped"
    finally:
        for peer in peers:
            peer.close()
