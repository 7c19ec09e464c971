"""`rosrun fleet_console fleet_console`: serves the operator's web page on the broker's machine.

As a ROS node (the fleet launches' console:=true, or alone beside a running fleet) it reads its private
parameters, waits for the broker URL the fleet's run_broker sets, draws the map from the fleet's map server and
passes the fleet's /diagnostics to logged-in pages. Without ROS (``--no-ros``) it needs --broker-url and takes
the map from --map-file. Either way it prints where to point the browser.
"""
import argparse
import math
import os
import signal
import ssl
import sys
import threading
import time

from coaty_bridge.config import parse_broker_url
from coaty_bridge.security import credentials_dir as default_credentials_dir, is_loopback
from fleet_console import mapimage
from fleet_console.server import ConsoleServer, ConsoleState

DEFAULTS = {"host": "127.0.0.1", "port": 8880, "broker_url": "", "broker_url_param": "/fleet/broker_url",
            "broker_wait": 60.0, "namespace": "fleet", "object_type": "org.fleetsharing.SharedObstacle",
            "map_topic": "/map", "map_file": "", "credentials_dir": "", "obstacle_duration": 1200,
            "url_param": "/fleet/console_url", "tls_cert": "", "tls_key": "", "insecure": False}


def parse_args(argv):
    parser = argparse.ArgumentParser(description="the fleet console: a web page on the fleet's Coaty bus")
    parser.add_argument("--no-ros", action="store_true", help="run without a ROS master")
    for name, default in DEFAULTS.items():
        flag = "--" + name.replace("_", "-")
        if isinstance(default, bool):
            parser.add_argument(flag, action="store_true", default=None)
        else:
            parser.add_argument(flag, type=type(default), default=None)
    args, _ = parser.parse_known_args([a for a in argv if ":=" not in a])
    return args


def settings(args, rospy):
    """Command line, then private parameters, then the defaults; checked, with the bad one named."""
    out = {}
    for name, default in DEFAULTS.items():
        value = getattr(args, name)
        if value is None and rospy is not None:
            value = rospy.get_param("~" + name, default)
        out[name] = default if value is None else value
    if isinstance(out["port"], bool) or not isinstance(out["port"], int) or not 0 <= out["port"] <= 65535:
        raise ValueError("parameter port = %r: must be 0..65535" % (out["port"],))
    if not (out["tls_cert"] and out["tls_key"]) and not is_loopback(out["host"]) and not out["insecure"]:
        raise ValueError("parameter host = %r: a console reachable from other machines needs tls_cert and tls_key "
                         "(the operator's login crosses the network), or insecure: true" % (out["host"],))
    if bool(out["tls_cert"]) != bool(out["tls_key"]):
        raise ValueError("parameters tls_cert and tls_key go together")
    duration = out["obstacle_duration"]
    if isinstance(duration, bool) or not isinstance(duration, (int, float)) or not math.isfinite(duration) \
            or duration < 1:
        raise ValueError("parameter obstacle_duration = %r: seconds, at least 1" % (duration,))
    out["obstacle_duration"] = int(math.ceil(duration))
    out["credentials_dir"] = default_credentials_dir(out["credentials_dir"] or None)
    return out


def wait_broker_url(conf, rospy):
    if conf["broker_url"]:
        return conf["broker_url"]
    if rospy is None:
        raise ValueError("--broker-url is needed without ROS (the fleet's broker, e.g. mqtt://127.0.0.1:1883)")
    deadline = time.monotonic() + conf["broker_wait"]
    while not rospy.is_shutdown():
        if rospy.has_param(conf["broker_url_param"]):
            return rospy.get_param(conf["broker_url_param"])
        if time.monotonic() > deadline:
            raise ValueError("no broker URL: parameter %s not set within %g s (is the fleet's run_broker up?)"
                             % (conf["broker_url_param"], conf["broker_wait"]))
        time.sleep(0.2)
    raise ValueError("shut down while waiting for %s" % conf["broker_url_param"])


def watch_ros(state, conf, rospy):
    """The map from the fleet's map server, and the fleet's /diagnostics, into the state."""
    from diagnostic_msgs.msg import DiagnosticArray
    from nav_msgs.msg import OccupancyGrid

    def on_map(msg):
        info = msg.info
        try:
            state.set_map(mapimage.from_grid(msg.data, float(info.resolution), info.origin.position.x,
                                             info.origin.position.y, int(info.width), int(info.height),
                                             conf["map_topic"]))
        except mapimage.MapError as err:
            rospy.logwarn("fleet_console: %s", err)
            state.set_map(None, str(err))

    def on_diagnostics(msg):
        for status in msg.status:
            if status.name.startswith(("coaty_bridge", "sharing_handler", "vda5050")):
                state.set_diagnostic(status.name, status.level, status.message,
                                     {kv.key: kv.value for kv in status.values}, msg.header.stamp.to_sec())
    if not conf["map_file"]:
        rospy.Subscriber(conf["map_topic"], OccupancyGrid, on_map, queue_size=1)
    rospy.Subscriber("/diagnostics", DiagnosticArray, on_diagnostics, queue_size=50)


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    args = parse_args(argv)
    rospy = None
    if not args.no_ros:
        import rospy
        rospy.init_node("fleet_console", disable_signals=True)
    log = (rospy.loginfo if rospy else lambda text, *a: print(text % a, flush=True))
    try:
        conf = settings(args, rospy)
        url = wait_broker_url(conf, rospy)
        address = parse_broker_url(url)
        if address.tls:
            raise ValueError("broker %s: the console reaches the broker on its plain loopback listener (run it on "
                             "the broker's machine)" % url)
    except ValueError as err:
        sys.stderr.write("fleet_console: %s\n" % err)
        return 2
    state = ConsoleState()
    if conf["map_file"]:
        try:
            state.set_map(mapimage.from_yaml(conf["map_file"]))
        except mapimage.MapError as err:
            state.set_map(None, str(err))
            log("fleet_console: %s (the page says so; the console runs without a map)", err)
    elif rospy is None:
        state.set_map(None, "no map: give --map-file (a map_server YAML file) or run with ROS")
    if rospy is not None:
        watch_ros(state, conf, rospy)
    context = None
    if conf["tls_cert"]:
        context = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
        context.load_cert_chain(conf["tls_cert"], conf["tls_key"])
    server = ConsoleServer(address.host, address.port, state, conf["namespace"], conf["object_type"], conf["host"],
                           conf["port"], conf["credentials_dir"], conf["obstacle_duration"], context)
    try:
        server.start()
    except RuntimeError as err:
        sys.stderr.write("%s\n" % err)
        return 1
    if rospy is not None and conf["url_param"]:
        rospy.set_param(conf["url_param"], server.url)
    log("fleet_console: point a browser at %s (MQTT over WebSocket to the broker %s; logins: rosrun coaty_bridge "
        "fleet_credentials add-operator|add-viewer NAME)", server.url, url)
    done = threading.Event()
    signal.signal(signal.SIGINT, lambda *a: done.set())
    signal.signal(signal.SIGTERM, lambda *a: done.set())
    while not done.wait(0.5):
        if rospy is not None and rospy.is_shutdown():
            break
    server.stop()
    if rospy is not None and conf["url_param"]:
        try:
            rospy.delete_param(conf["url_param"])
        except Exception:
            pass
    return 0
