"""No single crash stops the fleet (issue 43, item 8), on the running default launch: `fleet.launch robots:=3`
(simulator, map, run_broker, and per robot fleet_nav with the sharing layer, sharing_handler and coaty_bridge,
secure and with plausible evidence), its own master and ROS_HOME.

Before issue 43 the broker and every bridge were `required="true"`: killing mosquitto or one bridge stopped the
simulator and every robot, and a restart lost every shared obstacle. Now, one after the other:
- mosquitto is killed (SIGKILL; run_broker starts it again on the same port),
- robot_1's coaty_bridge is killed (roslaunch starts it again; it asks its peers on connecting),
- robot_2's sharing_handler is killed (started again; its bridge asks the fleet again and hands back robot_2's
  own updates),
and after each every robot holds the same obstacles again, none lost, and the simulator, the map server and
the other robots' nodes keep running (same pids). The time from the restart to the last robot holding them
all again is printed; asserted <= 10 s only with FLEET_ASSERT_LATENCY=1 (a loaded 2-core machine makes a
wall-clock bound flaky); otherwise the test waits for the outcome up to 90 s."""
import json
import os
import signal
import subprocess
import sys
import threading
import time
import xmlrpc.client

import pytest

from coaty_bridge.broker import free_port

ENV = dict(os.environ, ROS_IP="127.0.0.1", ROS_HOSTNAME="127.0.0.1")
ROBOTS = ("robot_0", "robot_1", "robot_2")
HERE = os.path.dirname(os.path.abspath(__file__))
WAIT = 90.0
RESTORE_BOUND = 10.0


def wait_until(predicate, what, timeout=WAIT):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = predicate()
        if value:
            return value
        time.sleep(0.1)
    raise AssertionError("timed out after %.0f s waiting for %s" % (timeout, what))


class Probe:
    def __init__(self, env):
        self.events, self.lock = [], threading.Lock()
        self.proc = subprocess.Popen([sys.executable, os.path.join(HERE, "crash_probe.py")] + list(ROBOTS),
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                                     text=True, env=env, bufsize=1)
        threading.Thread(target=self._read, daemon=True).start()
        self.next_id = 0

    def _read(self):
        for line in self.proc.stdout:
            try:
                event = json.loads(line)
            except ValueError:
                continue
            with self.lock:
                self.events.append(event)

    def latest(self, kind, robot):
        with self.lock:
            for event in reversed(self.events):
                if event.get("event") == kind and event.get("robot") == robot:
                    return event
        return None

    def add(self, robot, rect):
        self.next_id += 1
        self.proc.stdin.write(json.dumps({"cmd": "add", "id": self.next_id, "robot": robot, "rect": rect}) + "\n")
        self.proc.stdin.flush()
        ident = self.next_id
        reply = wait_until(lambda: next((e for e in list(self.events) if e.get("event") == "reply"
                                         and e.get("id") == ident), None), "the add_obstacle reply")
        assert reply["success"], reply
        return reply["uuid"]

    def lists(self):
        return {r: (self.latest("list", r) or {}).get("obstacles") for r in ROBOTS}

    def close(self):
        self.proc.stdin.close()
        self.proc.terminate()
        self.proc.wait(10)


class Fleet:
    def __init__(self, tmp_path):
        import rosgraph
        self.port = free_port()
        self.env = dict(ENV, ROS_MASTER_URI="http://127.0.0.1:%d" % self.port, ROS_HOME=str(tmp_path / "ros_home"))
        self.log = open(str(tmp_path / "launch.log"), "w")
        self.launch = subprocess.Popen(["roslaunch", "-p", str(self.port), "fleet_launch", "fleet.launch",
                                        "robots:=%d" % len(ROBOTS)], stdout=self.log, stderr=subprocess.STDOUT,
                                       env=self.env, start_new_session=True)
        self.master = rosgraph.Master("/test_fleet_crashes", master_uri=self.env["ROS_MASTER_URI"])
        self.tmp_path = tmp_path
        wait_until(lambda: self.param("/fleet/broker_url"), "the broker's URL", timeout=120)
        self.probe = Probe(self.env)

    def param(self, name):
        try:
            return self.master.getParam(name)
        except Exception:   # noqa: BLE001 - not set yet
            assert self.launch.poll() is None, self.tail()
            return None

    def tail(self):
        with open(str(self.tmp_path / "launch.log"), errors="replace") as log:
            return log.read()[-4000:]

    def pid(self, node):
        try:
            uri = self.master.lookupNode(node)
            code, _msg, pid = xmlrpc.client.ServerProxy(uri).getPid("/test_fleet_crashes")
            return pid if code == 1 else None
        except Exception:   # noqa: BLE001 - not up (yet, or any more)
            return None

    def mosquitto_pid(self):
        broker = self.pid("/fleet_broker")
        if broker is None:
            return None
        out = subprocess.run(["pgrep", "-P", str(broker), "mosquitto"], capture_output=True, text=True).stdout.split()
        return int(out[0]) if out else None

    def close(self):
        self.probe.close()
        if self.launch.poll() is None:
            os.killpg(self.launch.pid, signal.SIGINT)
            try:
                self.launch.wait(60)
            except subprocess.TimeoutExpired:
                os.killpg(self.launch.pid, signal.SIGKILL)
                self.launch.wait()
        self.log.close()


@pytest.fixture
def fleet(tmp_path):
    f = Fleet(tmp_path)
    yield f
    f.close()


def all_hold(fleet, uuids):
    """True when every robot's latest list holds exactly the same obstacles (uuids and cells) and all of ``uuids``."""
    lists = fleet.probe.lists()
    if any(v is None for v in lists.values()):
        return False
    first = lists[ROBOTS[0]]
    return set(uuids) <= set(first) and all(v == first for v in lists.values())


def summary(fleet):
    return {r: {u[:8]: len(c) for u, c in (v or {}).items()} for r, v in fleet.probe.lists().items()}


def restored_after(fleet, what, uuids, restarted_at):
    try:
        wait_until(lambda: all_hold(fleet, uuids), "every robot holding the same obstacles again after " + what)
    except AssertionError as err:
        raise AssertionError("%s; the lists (uuid: cells): %s" % (err, summary(fleet))) from None
    took = time.monotonic() - restarted_at
    print("after %s every robot held the same %d obstacles again %.1f s after the restart" % (what, len(uuids), took))
    if os.environ.get("FLEET_ASSERT_LATENCY") == "1":
        assert took <= RESTORE_BOUND, "%s: %.1f s" % (what, took)
    return took


def on_the_wall_below(pose, shift=0.0):
    """A 0.3 m x 0.1 m obstacle on the facility's bottom wall (y 0..0.2 m in the map) below a robot at its start
    (y ~1 m): within its sensor reach (plausible evidence), and where no beam can show it free (the robots' own
    evidence would otherwise end an obstacle made up in free space)."""
    x = pose["x"] + shift
    return [x - 0.15, 0.05, x + 0.15, 0.15]


def kill_and_wait_restart(fleet, pid_of, what):
    before = pid_of()
    assert before, "no pid for " + what
    os.kill(before, signal.SIGKILL)
    return before, wait_until(lambda: (pid_of() or before) != before and pid_of(), what + " started again")


def fresh_obstacle_reaches_everyone(fleet, uuids, robot, shift, what):
    """``robot`` shares a new obstacle: every robot lists it (the bus works again), the others still there."""
    fresh = fleet.probe.add(robot, on_the_wall_below(fleet.probe.latest("pose", robot), shift=shift))
    try:
        wait_until(lambda: all_hold(fleet, uuids + [fresh]), "%s's fresh obstacle on every robot after %s" % (robot, what))
    except AssertionError as err:
        raise AssertionError("%s; the lists (uuid: cells): %s" % (err, summary(fleet))) from None
    uuids.append(fresh)


def test_killing_the_broker_a_bridge_and_a_handler_stops_nothing_and_loses_no_obstacle(fleet):
    world = {name: wait_until(lambda n=name: fleet.pid(n), name + " up", timeout=120)
             for name in ("/fleet_sim", "/map_server")}
    for robot in ROBOTS:
        wait_until(lambda r=robot: fleet.probe.latest("list", r) and fleet.probe.latest("pose", r),
                   robot + "'s list and pose", timeout=120)
    navigation = {r: fleet.pid("/%s/move_base" % r) for r in ROBOTS}
    # each robot shares an obstacle on the wall below where it stands (within its reach: plausible evidence)
    uuids = []
    for robot in ROBOTS:
        uuids.append(fleet.probe.add(robot, on_the_wall_below(fleet.probe.latest("pose", robot))))
    wait_until(lambda: all_hold(fleet, uuids), "every robot holding the three obstacles")

    kill_and_wait_restart(fleet, fleet.mosquitto_pid, "mosquitto")
    restored_after(fleet, "the broker was killed", uuids, time.monotonic())
    fresh_obstacle_reaches_everyone(fleet, uuids, "robot_0", 0.9, "the broker restart")

    kill_and_wait_restart(fleet, lambda: fleet.pid("/robot_1/coaty_bridge"), "robot_1's coaty_bridge")
    restored_after(fleet, "robot_1's bridge was killed", uuids, time.monotonic())
    fresh_obstacle_reaches_everyone(fleet, uuids, "robot_1", -0.6, "robot_1's bridge restart")

    mark = len(fleet.probe.events)
    kill_and_wait_restart(fleet, lambda: fleet.pid("/robot_2/sharing_handler"), "robot_2's sharing_handler")
    restarted = time.monotonic()
    # judged on the lists of the new handler (it starts empty), not the last one of the killed one
    wait_until(lambda: [e for e in fleet.probe.events[mark:] if e.get("event") == "list" and e["robot"] == "robot_2"],
               "a list of robot_2's new handler")
    with fleet.probe.lock:
        first = [e for e in fleet.probe.events[mark:] if e.get("event") == "list" and e["robot"] == "robot_2"][0]
    print("robot_2's new handler's first list held %d obstacles" % len(first["obstacles"]))
    restored_after(fleet, "robot_2's handler was killed", uuids, restarted)
    fresh_obstacle_reaches_everyone(fleet, uuids, "robot_2", -0.6, "robot_2's handler restart")

    # the rest never stopped
    assert fleet.launch.poll() is None, fleet.tail()
    for name, pid in world.items():
        assert fleet.pid(name) == pid, name + " was restarted or stopped"
    assert {r: fleet.pid("/%s/move_base" % r) for r in ROBOTS} == navigation
