"""The deployment recipe in README.md ("A broker on another machine: TLS") works as written
(issue 27, item 9: its certificate snippet used to fail with `Can't open "pki/ca.key"`, and a
mosquitto started as root could not read the 0600 key). The sh block after the
`<!-- deploy-recipe -->` marker is run as it stands with bash, in an empty folder, with only ETC
(where /etc/mosquitto would be), PORT and BROKER set; mosquitto is started on the mosquitto.conf
it wrote (as root it drops to the user mosquitto, as the system service does), and two bridges
with the README's bridge parameters share an obstacle over mqtts://, while a client without
certificate and one publishing under another robot's sourceId get nowhere. Run as root, and, when
the test runs as root, also as the user nobody (a normal user)."""
import functools
import os
import pwd
import re
import shutil
import subprocess
import sys
import tempfile
import time
import uuid as uuidlib

import pytest

from coaty_bridge import codec
from coaty_bridge.broker import free_port
from coaty_bridge.client import BridgeConfig, CoatyBridgeClient, _make_paho_client
from coaty_bridge.identity import identity_for
from polling import join_after, wait_until

pytestmark = pytest.mark.broker
PKG = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
README = os.path.join(PKG, "README.md")
NS = "fleet"


def recipe():
    text = open(README).read()
    match = re.search(r"<!-- deploy-recipe -->\n```sh\n(.*?)\n```", text, re.S)
    assert match, "README.md has no sh block after <!-- deploy-recipe -->"
    return match.group(1) + "\n"


wait_for = functools.partial(wait_until, timeout=15.0, interval=0.05)


def run_recipe(user, tmp):
    """Runs the recipe as ``user`` (None: as we are) in ``tmp``/work; returns (etc, port, pki)."""
    work, etc = os.path.join(tmp, "work"), os.path.join(tmp, "etc_mosquitto")
    os.makedirs(work)
    home = os.path.join(tmp, "ros_home")
    os.makedirs(home)
    env = dict(os.environ, ETC=etc, PORT=str(free_port()), BROKER="localhost", ROS_HOME=home)
    argv = ["bash", "-euo", "pipefail", "-c", recipe()]
    if user:
        entry = pwd.getpwnam(user)
        for path in (tmp, work, home):
            os.chown(path, entry.pw_uid, entry.pw_gid)
        env["HOME"] = home
        argv = ["setpriv", "--reuid", str(entry.pw_uid), "--regid", str(entry.pw_gid), "--clear-groups"] + argv
    proc = subprocess.run(argv, cwd=work, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                          timeout=120)
    assert proc.returncode == 0, "the README's recipe failed (as %s):\n%s" % (user or "root/self", proc.stdout[-2000:])
    for robot in ("robot_0", "robot_1"):   # its first command prints the logins
        assert "%s %s" % (robot, identity_for(NS, robot)) in proc.stdout
    return etc, int(env["PORT"]), os.path.join(work, "pki")


@pytest.fixture(params=["as_we_are", "as_nobody"])
def deployed(request):
    if not shutil.which("openssl") or not shutil.which("rospack"):
        pytest.skip("openssl or rospack missing")
    user = None
    if request.param == "as_nobody":
        if os.geteuid() != 0:
            pytest.skip("running as a normal user already (the as_we_are case)")
        user = "nobody"
    tmp = tempfile.mkdtemp(prefix="deploy_recipe_")
    os.chmod(tmp, 0o755)   # like /etc: mosquitto, dropped to its own user, must reach its files
    broker = None
    try:
        etc, port, pki = run_recipe(user, tmp)
        argv = ["/usr/sbin/mosquitto", "-c", os.path.join(etc, "mosquitto.conf")]
        if user:
            entry = pwd.getpwnam(user)
            argv = ["setpriv", "--reuid", str(entry.pw_uid), "--regid", str(entry.pw_gid), "--clear-groups"] + argv
        broker = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        import socket

        def listening():
            assert broker.poll() is None, "mosquitto exited: %s" % broker.stdout.read()
            try:
                socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
                return True
            except OSError:
                return False
        wait_for(listening, "mosquitto on the recipe's config")
        yield port, pki
    finally:
        if broker is not None and broker.poll() is None:
            broker.terminate()
            broker.wait(10)
        shutil.rmtree(tmp, ignore_errors=True)


def test_readme_recipe_as_written(deployed):
    port, pki = deployed
    clients, got_1 = [], []
    try:
        def bridge(robot, sink):
            ident = identity_for(NS, robot)
            # the README's bridge parameters, with the files where the recipe put them
            client = CoatyBridgeClient(BridgeConfig(
                robot, broker_url="mqtts://localhost:%d" % port, namespace=NS, authenticate_sources=True,
                tls_ca=os.path.join(pki, "ca.crt"), tls_cert=os.path.join(pki, ident + ".crt"),
                tls_key=os.path.join(pki, ident + ".key"), reconnect_min_delay=0.2, reconnect_max_delay=0.5),
                lambda u, t: sink.append(u))
            clients.append(client)
            client.start()
            return client
        robot_0 = bridge("robot_0", [])
        join_after(robot_0, lambda: bridge("robot_1", got_1), wait_for)
        update = codec.ObstacleUpdate(str(uuidlib.uuid4()), "robot_0", 1, 10.0, "map", 60, (0.0, 0.0, 1.0, 1.0),
                                      0.05, 0.0, 0.0, 100, 100, (5, 6), ())
        robot_0.publish_obstacle(update)
        wait_for(lambda: got_1 == [update], "robot_0's obstacle at robot_1 over TLS")
        # robot_1's certificate cannot publish under robot_0's sourceId: sourceId and source agree, so
        # robot_1's bridge would take it; only the broker's ACL stops it
        forger = _make_paho_client("forger-" + uuidlib.uuid4().hex[:8])
        ident_1 = identity_for(NS, "robot_1")
        forger.tls_set(ca_certs=os.path.join(pki, "ca.crt"), certfile=os.path.join(pki, ident_1 + ".crt"),
                       keyfile=os.path.join(pki, ident_1 + ".key"))
        forger.connect("localhost", port)
        forger.loop_start()
        forged = codec.ObstacleUpdate(str(uuidlib.uuid4()), "robot_0", 1, 10.0, "map", 60, (0.0, 0.0, 1.0, 1.0),
                                      0.05, 0.0, 0.0, 100, 100, (7,), ())
        topic = "coaty/3/%s/ADV::%s/%s" % (NS, codec.DEFAULT_OBJECT_TYPE, identity_for(NS, "robot_0"))
        forger.publish(topic, codec.advertise_payload(codec.obstacle_to_object(forged, codec.DEFAULT_OBJECT_TYPE)))
        time.sleep(0.8)
        forger.loop_stop()
        forger.disconnect()
        # (the forger's login is robot_1's; with another client id it is a second connection beside robot_1's)
        assert forged.uuid not in {u.uuid for u in got_1}, "robot_1 took an obstacle published under robot_0's sourceId"
        # no certificate, no connection
        plain = _make_paho_client("nocert-" + uuidlib.uuid4().hex[:8])
        plain.tls_set(ca_certs=os.path.join(pki, "ca.crt"))
        accepted = False
        try:
            plain.connect("localhost", port)
            for _ in range(30):
                if plain.loop(0.1) != 0:
                    break
                if plain.is_connected():
                    accepted = True
                    break
        except OSError:
            pass
        assert not accepted, "the broker took a client without certificate"
    finally:
        for client in clients:
            client.stop(timeout=0.5)
