"""Logins while the fleet runs (issue 43, items 6 and 9), through run_broker (as fleet.launch starts it, here
without ROS) and real bridge clients:
- a second connection under a robot's login leaves the robot connected (no reconnect, no last will) and
  shows in the robot's bridge as WARN, then ERROR when it happens again;
- a robot added with `fleet_credentials add` logs in without a broker restart, and refused before;
- `fleet_credentials rotate` makes the old secret useless without a restart: mosquitto lets the robot
  connected on it go, and its bridge logs in again at once with the new secret (it reads its password_file
  before each connection); the other robots stay;
- mosquitto killed under run_broker comes back on the same port, and the robots with it.
The log parser alone on mosquitto 2.0's own lines is tested first (pure)."""
import functools
import json
import os
import signal
import subprocess
import sys
import time

import pytest

from coaty_bridge import logins
from coaty_bridge.client import BridgeConfig, CoatyBridgeClient
from coaty_bridge.errors import OutOfRangeError, WrongTypeError
from coaty_bridge.identity import identity_for
from coaty_bridge.security import FleetCredentials, read_password_file

import polling
from test_secure_default import RUN_BROKER, Lines, Peer

NS = "fleet"
PKG = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FLEET_CREDENTIALS = os.path.join(PKG, "scripts", "fleet_credentials")
wait_until = functools.partial(polling.wait_until, timeout=20.0)

LOG = """1795903988: New connection from 127.0.0.1:34361 on port 18831.
1795903988: New client connected from 127.0.0.1:34361 as Coatyaaaa1111 (p2, c1, k60, u'LOGIN_A').
1795903989: New connection from 127.0.0.1:44917 on port 18831.
1795903989: Client <unknown> disconnected, not authorised.
1795903991: New client connected from 127.0.0.1:44477 as peer-1 (p2, c1, k60, u'LOGIN_A').
1795903991: New client connected from 127.0.0.1:44478 as other (p2, c1, k60, u'LOGIN_B').
1795903992: Client peer-1 disconnected.
1795903993: New client connected from 127.0.0.1:44480 as peer-2 (p2, c1, k60, u'LOGIN_A').
1795903994: Client peer-2 closed its connection.
1795903995: New client connected from 127.0.0.1:34999 as Coatyaaaa1111 (p2, c1, k60, u'LOGIN_A').
"""


def test_the_log_tells_each_second_connection_under_a_robots_login_and_no_other():
    log = logins.ConnectionLog({"LOGIN_A"})
    alerts = [a for a in (log.line(line) for line in LOG.splitlines()) if a]
    assert [(a.client_id, a.address, a.clients) for a in alerts] == [
        ("peer-1", "127.0.0.1:44477", ("Coatyaaaa1111", "peer-1")),
        ("peer-2", "127.0.0.1:44480", ("Coatyaaaa1111", "peer-2"))], \
        "a login not watched (LOGIN_B), a refusal and the robot reconnecting under its own id are no alert"
    shown = logins.LoginAlerts("robot_0", "Coatyaaaa1111", clock=lambda: 1000.0)
    assert shown.status() == (0, "")
    assert shown.note(alerts[0]) == ("peer-1",)
    level, text = shown.status()
    assert level == 1 and "peer-1" in text and "127.0.0.1:44477" in text and "fleet_credentials rotate robot_0" in text
    shown.note(alerts[1])
    assert shown.status()[0] == 2, "repeated: ERROR"
    assert shown.note(logins.LoginAlert("LOGIN_A", "Coatyaaaa1111", "x", ("Coatyaaaa1111",), 0.0)) is None


def _alert_data(**fields):
    obj = json.loads(logins.LoginAlert("LOGIN_A", "peer-1", "127.0.0.1:44477", ("Coatyaaaa1111", "peer-1"),
                                       1795903988.0).payload("5b8a2a3e-1111-4222-8333-444455556666"))
    obj["object"].update(fields)
    return obj


def test_a_received_alert_is_read_back_and_each_size_is_checked_at_its_limit():
    assert logins.LoginAlert.from_payload(_alert_data()).clients == ("Coatyaaaa1111", "peer-1")
    text, clients = logins.MAX_ALERT_TEXT, logins.MAX_ALERT_CLIENTS
    for field in ("login", "clientId", "address"):
        logins.LoginAlert.from_payload(_alert_data(**{field: "a" * text}))          # just inside
        for bad in ("a" * (text + 1), "", 7, None):                                   # just outside, and wrong
            with pytest.raises(OutOfRangeError):
                logins.LoginAlert.from_payload(_alert_data(**{field: bad}))
    logins.LoginAlert.from_payload(_alert_data(clients=["c%d" % i for i in range(clients)]))
    logins.LoginAlert.from_payload(_alert_data(clients=["a" * text]))
    for bad in (["c%d" % i for i in range(clients + 1)], [], ["a" * (text + 1)], [3], "peer-1"):
        with pytest.raises(OutOfRangeError):
            logins.LoginAlert.from_payload(_alert_data(clients=bad))
    for bad in (True, "1795903988", None):
        with pytest.raises(OutOfRangeError):
            logins.LoginAlert.from_payload(_alert_data(stamp=bad))
    for data in ({}, [], {"object": {"objectType": "other"}}):
        with pytest.raises(WrongTypeError):
            logins.LoginAlert.from_payload(data)


class Fleet:
    """run_broker --no-ros with robot_0 .. robot_2, and bridge clients logging in with their password files."""

    def __init__(self, folder, robots=3):
        self.folder = folder
        self.proc = subprocess.Popen([sys.executable, RUN_BROKER, "--no-ros", "--port", "0", "--robots", str(robots),
                                      "--credentials-dir", folder], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                     text=True)
        self.out = Lines(self.proc)
        wait_until(lambda: [l for l in self.out.lines if l.startswith("mqtt://")] or self.proc.poll() is not None,
                   "run_broker's URL")
        self.url = [l for l in self.out.lines if l.startswith("mqtt://")][0]
        self.port = int(self.url.rsplit(":", 1)[1])
        self.creds = FleetCredentials(folder, [], NS)
        self.clients, self.peers = [], []

    def bridge(self, robot):
        password_file = self.creds.password_file(robot)
        config = BridgeConfig(robot, broker_url=self.url, authenticate_sources=True, password_file=password_file,
                              password=read_password_file(password_file), reconnect_max_delay=1.0)
        client = CoatyBridgeClient(config, lambda u, t: None)
        client.start()
        self.clients.append(client)
        wait_until(lambda: client.subscribed, robot + " connected")
        return client

    def peer(self, robot=None, password=None, **kwargs):
        login = self.creds.login(robot) if robot else (None, None)
        peer = Peer(self.port, login[0], password or login[1], **kwargs)
        self.peers.append(peer)
        wait_until(peer.settled, "the broker's answer")
        return peer

    def credentials(self, *args):
        proc = subprocess.run([sys.executable, FLEET_CREDENTIALS] + list(args) + ["--credentials-dir", self.folder],
                              capture_output=True, text=True, timeout=30)
        return proc.returncode, proc.stdout + proc.stderr

    def mosquitto_pid(self):
        proc = subprocess.run(["pgrep", "-P", str(self.proc.pid), "mosquitto"], capture_output=True, text=True)
        return int(proc.stdout.split()[0]) if proc.stdout.split() else None

    def close(self):
        for peer in self.peers:
            peer.close()
        for client in self.clients:
            client.stop(timeout=0.5)
        self.proc.send_signal(signal.SIGINT)
        self.proc.wait(10)


@pytest.fixture
def fleet(tmp_path):
    f = Fleet(str(tmp_path / "creds"))
    yield f
    f.close()


@pytest.mark.broker
def test_a_second_connection_under_a_robots_login_leaves_it_connected_and_shows_in_its_bridge(fleet):
    """The issue: a 20 s hold of robot_2's login cost robot_2 39 reconnects and 15.7 s off the broker, while its
    diagnostics stayed OK."""
    robot = fleet.bridge("robot_2")
    watcher = fleet.peer("robot_0")          # robot_0's login, to see robot_2's last will should it come
    assert robot.login_alerts.status() == (0, "")
    held = fleet.peer("robot_2", subscribe=None)
    assert held.accepted
    wait_until(lambda: robot.login_alerts.status()[0] == 1, "robot_2's bridge WARNing about the other connection")
    level, text = robot.login_alerts.status()
    assert "robot_2" in text and "127.0.0.1" in text and "rotate robot_2" in text
    time.sleep(2.0)                          # held, as in the issue
    held.close()
    again = fleet.peer("robot_2", subscribe=None)
    wait_until(lambda: robot.login_alerts.status()[0] == 2, "robot_2's bridge at ERROR: repeated")
    again.close()
    assert robot.connected and robot.counters().get("reconnects", 0) == 0 and robot.counters().get("disconnects", 0) == 0
    assert not [t for t in watcher.topics() if t == "coaty/3/%s/DAD/%s" % (NS, identity_for(NS, "robot_2"))], \
        "robot_2 was cut off: the broker published its last will"
    # a wrong password under its login is refused and is no alert (only logins that got in are connections)
    wrong = fleet.peer("robot_2", password="guessed", subscribe=None)
    assert wrong.refused and robot.counters()["login_alerts"] == 2


@pytest.mark.broker
def test_a_robot_added_while_the_broker_runs_logs_in_without_a_restart(fleet):
    pid = fleet.mosquitto_pid()
    assert not (fleet.creds.login("robot_0") and os.path.exists(fleet.creds.password_file("robot_3")))
    stranger = fleet.peer(subscribe=None)
    assert stranger.refused
    code, out = fleet.credentials("add", "robot_3")
    assert code == 0 and "login added" in out
    wait_until(lambda: any("added robot_3" in l for l in fleet.out.lines), "run_broker reloading the logins")
    robot_3 = fleet.bridge("robot_3")
    assert robot_3.connected and fleet.mosquitto_pid() == pid, "mosquitto was restarted"
    code, out = fleet.credentials("add", "fleet_broker")
    assert code == 2 and "reserved" in out


@pytest.mark.broker
def test_a_rotated_secret_works_at_once_the_old_one_not_and_the_bridge_follows(fleet):
    robot = fleet.bridge("robot_0")
    old = read_password_file(fleet.creds.password_file("robot_0"))
    pid = fleet.mosquitto_pid()
    code, out = fleet.credentials("rotate", "robot_0")
    assert code == 0, out
    new = read_password_file(fleet.creds.password_file("robot_0"))
    assert new != old
    wait_until(lambda: any("new secret for robot_0" in l for l in fleet.out.lines), "run_broker reloading")
    assert fleet.peer("robot_0", password=old, subscribe=None).refused, "the old secret still logs in"
    assert fleet.peer("robot_0", password=new, subscribe=None).accepted
    # mosquitto checks connected clients against the reloaded logins: robot_0, on its old secret, is let go, and
    # its bridge logs in again at once with the new one; the broker is not restarted, the others stay
    other = fleet.bridge("robot_1")
    wait_until(lambda: robot.counters().get("password_reloaded") == 1 and robot.subscribed,
               "robot_0 back with its new secret")
    assert fleet.mosquitto_pid() == pid, "a rotation must not cost a restart"
    assert other.connected and other.counters().get("disconnects", 0) == 0
    # mosquitto killed under run_broker comes back on the same port, and the robots with it
    pid = fleet.mosquitto_pid()
    os.kill(pid, signal.SIGKILL)
    wait_until(lambda: not robot.connected, "robot_0 noticing the broker gone")
    wait_until(lambda: fleet.mosquitto_pid() not in (None, pid), "run_broker starting mosquitto again", timeout=20)
    wait_until(lambda: robot.subscribed, "robot_0 back, on the same URL, with its new secret", timeout=30)
    assert robot.counters()["password_reloaded"] == 1
    # run_broker says so once the new mosquitto is up: a bridge may be back before that line is read
    wait_until(lambda: any("started again on %s" % fleet.url in l for l in fleet.out.lines),
               "run_broker saying it started mosquitto again")
