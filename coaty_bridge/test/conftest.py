"""Shared fixtures of the coaty_bridge tests. The pure modules are imported from
src/ so the pure and broker tests run without a built workspace."""
import os
import sys
import time
import uuid as uuidlib

import pytest

from polling import wait_until

SRC = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "src")
if SRC not in sys.path:
    sys.path.insert(0, SRC)
# sharing_msgs' pure helpers (obstacle_rules) without a built workspace; appended, so a sourced
# workspace's sharing_msgs (with the generated msg package) wins.
MSGS_SRC = os.path.join(os.path.dirname(os.path.dirname(SRC)), "sharing_msgs", "src")
if MSGS_SRC not in sys.path:
    sys.path.append(MSGS_SRC)


def pytest_configure(config):
    config.addinivalue_line("markers", "broker: needs /usr/sbin/mosquitto (each test starts its own)")
    config.addinivalue_line("markers", "npm: installs @coaty/core from the npm registry and runs node")
    config.addinivalue_line("markers", "ros: starts a private rosmaster and the coaty_bridge node")


@pytest.fixture
def make_update():
    """Factory for valid ObstacleUpdates; keyword arguments override fields."""
    from coaty_bridge.codec import ObstacleUpdate

    def make(**fields):
        values = dict(uuid=str(uuidlib.uuid4()), source="robot_0", version=1, stamp=1700000000.5,
                      frame_id="map", deadline=60, rectangle=(1.0, 2.0, 3.5, 4.0), resolution=0.05,
                      origin_x=-10.0, origin_y=-20.0, size_x=2000, size_y=2000,
                      marked=(880221, 880222, 882223), cleared=(880220,))
        values.update(fields)
        return ObstacleUpdate(**values)
    return make


@pytest.fixture
def wait_for():
    def wait(predicate, timeout=5.0, what="condition"):
        return wait_until(predicate, what, timeout, interval=0.01)
    return wait


@pytest.fixture
def broker():
    from coaty_bridge.broker import Broker
    if not os.access("/usr/sbin/mosquitto", os.X_OK):
        pytest.skip("mosquitto is not installed (/usr/sbin/mosquitto)")
    with Broker() as running:
        yield running


@pytest.fixture
def obstacle_area_m():
    """The obstacle_area_size of make_client's clients: None, the bridge's default. A test module whose positions are
    laid out for another size overrides this fixture."""
    return None


@pytest.fixture
def make_client(broker, obstacle_area_m):
    """Factory for started CoatyBridgeClients on the test broker; all are stopped after."""
    from coaty_bridge.client import BridgeConfig, CoatyBridgeClient
    clients = []

    def make(robot_name, received=None, start=True, clock=None, **config):
        config.setdefault("broker_url", broker.url)
        if obstacle_area_m is not None:
            config.setdefault("obstacle_area_size", obstacle_area_m)
        sink = received if received is not None else []
        extra = {} if clock is None else {"clock": clock}   # an injected clock: now[0] of the test's own list
        client = CoatyBridgeClient(BridgeConfig(robot_name, **config), lambda u, t: sink.append(u), **extra)
        client.received_updates = sink
        clients.append(client)
        if start:
            client.start()
        return client
    yield make
    for client in clients:
        client.stop(timeout=0.5)


class Observer:
    """A plain paho client that records every message on the broker and can publish."""

    def __init__(self, url):
        import paho.mqtt.client as mqtt
        from coaty_bridge.client import _make_paho_client, parse_broker_url
        address = parse_broker_url(url)
        self.messages = []
        self._client = _make_paho_client("observer-" + uuidlib.uuid4().hex[:8])
        self._client.on_message = lambda c, u, m: self.messages.append((m.topic, bytes(m.payload)))
        subscribed = []
        self._client.on_subscribe = lambda *a: subscribed.append(True)
        self._client.connect(address.host, address.port)
        self._client.subscribe("#")
        self._client.loop_start()
        deadline = time.monotonic() + 5
        while not subscribed and time.monotonic() < deadline:
            time.sleep(0.01)
        assert subscribed, "observer could not subscribe"
        self._mqtt = mqtt

    def publish(self, topic, payload):
        self._client.publish(topic, payload).wait_for_publish(2)

    def on(self, fragment):
        """(topic, decoded JSON) of every message whose topic contains ``fragment``."""
        import json
        found = []
        for topic, payload in list(self.messages):
            if fragment in topic:
                try:
                    found.append((topic, json.loads(payload)))
                except ValueError:
                    found.append((topic, payload))
        return found

    def close(self):
        self._client.disconnect()
        self._client.loop_stop()


@pytest.fixture
def observer(broker):
    obs = Observer(broker.url)
    yield obs
    obs.close()


class JsonLinesProcess:
    """A child process that speaks JSON lines: send() writes a command, expect() waits
    for an event matching a predicate (events are kept, so order does not matter)."""

    def __init__(self, name, argv, env=None, cwd=None):
        import subprocess
        import threading
        self.name = name
        self.events = []
        self.stderr_tail = []
        self._stdout_done = False
        self._cond = threading.Condition()
        self.proc = subprocess.Popen(argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, env=env, cwd=cwd, text=True, bufsize=1)
        threading.Thread(target=self._read_stdout, daemon=True).start()
        threading.Thread(target=self._read_stderr, daemon=True).start()

    def _read_stdout(self):
        import json
        for line in self.proc.stdout:
            try:
                event = json.loads(line)
            except ValueError:
                event = {"event": "text", "text": line.rstrip()}
            with self._cond:
                self.events.append(event)
                self._cond.notify_all()
        with self._cond:
            self._stdout_done = True
            self._cond.notify_all()

    def _read_stderr(self):
        for line in self.proc.stderr:
            self.stderr_tail = (self.stderr_tail + [line.rstrip()])[-30:]

    def send(self, command):
        import json
        self.proc.stdin.write(json.dumps(command) + "\n")
        self.proc.stdin.flush()

    def expect(self, predicate, timeout=15.0, what="event"):
        deadline = time.monotonic() + timeout
        with self._cond:
            while True:
                for event in self.events:
                    if predicate(event):
                        return event
                left = deadline - time.monotonic()
                if left <= 0 or self._stdout_done:
                    raise AssertionError("%s: no %s within %.0f s%s; last events %s; stderr %s" % (
                        self.name, what, timeout, " (process ended)" if self._stdout_done else "",
                        self.events[-8:], "\n".join(self.stderr_tail[-10:])))
                self._cond.wait(min(left, 0.2))

    def stop(self, timeout=5.0):
        import subprocess
        if self.proc.poll() is None:
            try:
                self.proc.stdin.close()
            except OSError:
                pass
            self.proc.terminate()
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


class RosGraph:
    """A private rosmaster on a free port plus helpers to start coaty_bridge nodes."""

    PKG = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

    def __init__(self):
        import subprocess
        from coaty_bridge.broker import free_port
        self.port = free_port()
        self.env = dict(os.environ, ROS_MASTER_URI="http://127.0.0.1:%d" % self.port,
                        ROS_IP="127.0.0.1", ROS_HOSTNAME="127.0.0.1",
                        PYTHONPATH=SRC + os.pathsep + os.environ.get("PYTHONPATH", ""),
                        ROS_LOG_DIR=os.environ.get("ROS_LOG_DIR", "/tmp/coaty_bridge_test_logs"))
        self.master = subprocess.Popen(["rosmaster", "--core", "-p", str(self.port)], env=self.env,
                                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        deadline = time.monotonic() + 10
        import socket
        while True:
            try:
                socket.create_connection(("127.0.0.1", self.port), timeout=0.2).close()
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise AssertionError("rosmaster did not start")
                time.sleep(0.05)
        self.nodes = []

    def bridge(self, robot, *params):
        """Starts robot/coaty_bridge with private params given as 'name:=value' strings."""
        import subprocess
        argv = [sys.executable, os.path.join(self.PKG, "scripts", "coaty_bridge"),
                "__ns:=" + robot, "__name:=coaty_bridge"] + ["_" + p for p in params]
        proc = subprocess.Popen(argv, env=self.env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.nodes.append(proc)
        return proc

    def probe(self, *robots):
        proc = JsonLinesProcess("bridge_probe", [sys.executable, os.path.join(self.PKG, "test", "bridge_probe.py")]
                                + list(robots), env=self.env)
        self.nodes.append(proc)
        proc.expect(lambda e: e.get("event") == "ready", what="probe ready")
        return proc

    def close(self):
        import signal
        import subprocess
        for node in reversed(self.nodes):
            if isinstance(node, JsonLinesProcess):
                node.stop()
            elif node.poll() is None:
                node.send_signal(signal.SIGINT)
                try:
                    node.wait(5)
                except subprocess.TimeoutExpired:
                    node.kill()
                    node.wait()
        self.master.terminate()
        self.master.wait(5)


def ros_unavailable():
    """Why the ROS tests cannot run here, or None."""
    import shutil
    if not shutil.which("rosmaster"):
        return "rosmaster not installed"
    try:
        import rospy  # noqa: F401
        from sharing_msgs.msg import SharedObstacle  # noqa: F401
        from diagnostic_msgs.msg import DiagnosticArray  # noqa: F401
    except ImportError as err:
        return "ROS workspace not built or not sourced (%s)" % err
    return None


def _ros_graph():
    reason = ros_unavailable()
    if reason:
        pytest.skip(reason)
    graph = RosGraph()
    graph.json_lines_process = JsonLinesProcess
    yield graph
    graph.close()


@pytest.fixture
def ros_graph():
    yield from _ros_graph()


@pytest.fixture
def json_lines_process():
    """The JsonLinesProcess class (tests must not import conftest by name)."""
    return JsonLinesProcess


@pytest.fixture
def observer_factory():
    made = []

    def make(url):
        obs = Observer(url)
        made.append(obs)
        return obs
    yield make
    for obs in made:
        try:
            obs.close()
        except Exception:
            pass


@pytest.fixture(scope="module")
def module_ros_graph():
    """One private rosmaster for a whole module (tests whose nodes start once; test_attacks_nodes.py)."""
    yield from _ros_graph()
