"""fleet_console.server and the node's settings, pure (no ROS, no broker: a TCP echo stands in for it). Bad
requests, bad logins and bad parameters get an answer that names the problem, and the server goes on serving."""
import asyncio
import http.client
import json
import socket
import threading
from types import SimpleNamespace

import pytest
import websockets

from coaty_bridge.security import FleetCredentials
from fleet_console import mapimage, node
from fleet_console.server import ConsoleServer, ConsoleState
from sharing_msgs.authority import OPERATOR_VERSION_MARGIN


class Echo:
    """A TCP server that sends back what it gets: the broker's side of the pass-through."""

    def __init__(self):
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(8)
        self.port = self.sock.getsockname()[1]
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self):
        while True:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            threading.Thread(target=self._echo, args=(conn,), daemon=True).start()

    @staticmethod
    def _echo(conn):
        with conn:
            while True:
                data = conn.recv(65536)
                if not data:
                    return
                conn.sendall(data)


def closed_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def console(tmp_path):
    creds = FleetCredentials.ensure(str(tmp_path / "fleet_security"), ["robot_0"])
    secrets = {name: open(creds.add_console_login(name, role)).read().strip()
               for name, role in (("anna", "operator"), ("olga", "viewer"))}
    secrets["robot_0"] = open(creds.password_file("robot_0")).read().strip()
    secrets["broker"] = open(str(tmp_path / "fleet_security" / "broker.password")).read().strip()
    echo = Echo()
    state = ConsoleState()
    server = ConsoleServer("127.0.0.1", echo.port, state, credentials_dir=creds.directory).start()
    yield SimpleNamespace(server=server, state=state, secrets=secrets, echo=echo)
    server.stop()
    echo.sock.close()


def get(server, path, headers=None):
    conn = http.client.HTTPConnection("127.0.0.1", server.port, timeout=10)
    try:
        conn.request("GET", path, headers=headers or {})
        reply = conn.getresponse()
        return reply.status, reply.read()
    finally:
        conn.close()


def still_serves(server):
    status, body = get(server, "/config.json")
    assert status == 200 and json.loads(body)["namespace"] == "fleet"


def test_config_says_why_there_is_no_map_and_gives_the_operator_margin(console):
    status, body = get(console.server, "/config.json")
    config = json.loads(body)
    assert status == 200 and config["map"] is None and "no map yet" in config["mapError"]
    assert config["versionMargin"] == OPERATOR_VERSION_MARGIN
    status, body = get(console.server, "/map.png")
    assert status == 404 and b"no map: no map yet" in body
    console.state.set_map(None, "map file x.yaml is not YAML: oops")
    assert json.loads(get(console.server, "/config.json")[1])["mapError"] == "map file x.yaml is not YAML: oops"
    console.state.set_map(mapimage.from_grid([0, 100], 0.5, 0, 0, 2, 1))
    config = json.loads(get(console.server, "/config.json")[1])
    assert config["mapError"] is None and config["map"]["width"] == 2 and config["map"]["version"] == 2
    status, body = get(console.server, "/map.png")
    assert status == 200 and body.startswith(b"\x89PNG")


@pytest.mark.parametrize("path", ["/web/../../etc/passwd", "/web/..%2f..%2fetc%2fpasswd", "/web/.hidden",
                                  "/web/sub/console.js", "/web/", "/vendor/other.js", "/vendor/../setup.py",
                                  "/nothing", "/" + "x" * 5000])
def test_paths_outside_the_page_are_not_found(console, path):
    status, body = get(console.server, path)
    assert status in (404, 400), (path, status, body[:200])   # 400: a request line too long for websockets
    assert b"root:" not in body
    still_serves(console.server)


def test_the_page_and_its_scripts_are_served(console):
    for path in ("/", "/index.html", "/web/console.js", "/web/model.js"):
        assert get(console.server, path)[0] == 200, path


@pytest.mark.parametrize("name,status,role", [("anna", 200, "operator"), ("olga", 200, "viewer"),
                                              ("someone", 200, ""), ("", 400, None), ("a/b", 400, None),
                                              ("a%2B", 400, None), ("%23", 400, None), ("..%2fbroker", 400, None)])
def test_identity_gives_a_names_role_and_refuses_what_cannot_be_a_coaty_name(console, name, status, role):
    code, body = get(console.server, "/identity?name=" + name)
    reply = json.loads(body)
    assert code == status, reply
    if status == 200:
        assert reply["role"] == role and len(reply["identity"]) == 36
    else:
        assert "is not a Coaty name" in reply["error"]


@pytest.mark.parametrize("login,status", [
    (None, 403), ("", 403), ("anna", 403), ("anna:", 403), ("anna:wrong", 403), ("nobody:x", 403),
    ("robot_0:{robot_0}", 403),              # a robot's login is not a console login
    ("../broker:{broker}", 403),             # nor, by a path, the broker's own
    ("../robots/robot_0:{robot_0}", 403),
    ("anna:{anna}", 200), ("olga:{olga}", 200),
])
def test_health_is_served_only_to_a_console_login(console, login, status):
    headers = {} if login is None else {"X-Fleet-Login": login.format(**console.secrets)}
    console.state.set_diagnostic("coaty_bridge robot_0", 1, "flooded", {"dropped": "3"})
    code, body = get(console.server, "/health.json", headers)
    reply = json.loads(body)
    assert code == status, reply
    if status == 200:
        assert reply["diagnostics"][0]["message"] == "flooded" and "http_requests" in reply["server"]
    else:
        assert reply == {"error": "health needs a console login"}


def test_a_route_that_fails_is_a_500_and_the_server_goes_on(console):
    def broken():
        raise RuntimeError("state gone")
    real = console.state.snapshot
    console.state.snapshot = broken
    status, body = get(console.server, "/config.json")
    assert status == 500 and b"state gone" in body
    console.state.snapshot = real
    still_serves(console.server)


@pytest.mark.parametrize("raw", [b"GARBAGE\r\n\r\n", b"GET / HTTP/1.1\r\nHost: x\r\nbroken header\r\n\r\n",
                                 b"\x00\xff" * 100 + b"\r\n\r\n", b"GET /" + b"a" * 100000 + b" HTTP/1.1\r\n\r\n",
                                 b"POST /config.json HTTP/1.1\r\nContent-Length: 5\r\n\r\nhello", b"GET"])
def test_malformed_requests_get_no_page_and_the_server_goes_on(console, raw):
    with socket.create_connection(("127.0.0.1", console.server.port), timeout=10) as sock:
        sock.sendall(raw)
        sock.shutdown(socket.SHUT_WR)
        reply = b""
        try:
            while True:
                data = sock.recv(65536)
                if not data:
                    break
                reply += data
        except (ConnectionResetError, socket.timeout):
            pass
    assert not reply.startswith(b"HTTP/1.1 200"), reply[:200]
    still_serves(console.server)


def ws_exchange(port, payloads):
    async def run():
        async with websockets.connect("ws://127.0.0.1:%d/mqtt" % port, subprotocols=["mqtt"]) as ws:
            got = b""
            for payload in payloads:
                await ws.send(payload)
            want = sum(len(p) for p in payloads)
            while len(got) < want:
                got += await asyncio.wait_for(ws.recv(), 10)
            return got
    return asyncio.run(run())


def test_the_websocket_carries_bytes_to_the_broker_and_back_unchanged(console):
    payloads = [b"\x10\x0c\x00\x04MQTT\x04\x02\x00\x3c", bytes(range(256)), b"x" * 100000]
    assert ws_exchange(console.server.port, payloads) == b"".join(payloads)
    assert console.server.connections == 0 or console.server.connections == 1
    still_serves(console.server)


def test_an_unreachable_broker_closes_the_websocket_saying_so(tmp_path):
    server = ConsoleServer("127.0.0.1", closed_port(), ConsoleState()).start()
    try:
        async def run():
            async with websockets.connect("ws://127.0.0.1:%d/mqtt" % server.port) as ws:
                with pytest.raises(websockets.ConnectionClosed) as closed:
                    await asyncio.wait_for(ws.recv(), 10)
                return closed.value
        closed = asyncio.run(run())
        assert closed.code == 1011 and "cannot be reached" in closed.reason
        assert server.counters["broker_unreachable"] == 1
        still_serves(server)
    finally:
        server.stop()


def test_a_port_in_use_is_an_error_naming_it():
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        with pytest.raises(RuntimeError, match="could not listen on 127.0.0.1:%d" % taken.getsockname()[1]):
            ConsoleServer("127.0.0.1", 1, ConsoleState(), port=taken.getsockname()[1]).start()


# ---------------------------------------------------------------- the node's parameters

@pytest.mark.parametrize("argv,text", [
    (["--port", "-1"], "parameter port = -1: must be 0..65535"),
    (["--port", "70000"], "parameter port = 70000"),
    (["--host", "0.0.0.0"], "parameter host = '0.0.0.0': a console reachable from other machines needs tls_cert"),
    (["--tls-cert", "c.pem"], "tls_cert and tls_key go together"),
    (["--obstacle-duration", "0"], "parameter obstacle_duration = 0: seconds, at least 1"),
    (["--obstacle-duration", "-5"], "parameter obstacle_duration = -5"),
])
def test_bad_parameters_are_refused_naming_them(argv, text):
    with pytest.raises(ValueError, match=text.replace("(", r"\(").replace(".", r"\.")):
        node.settings(node.parse_args(argv), None)


class FakeRospy:
    def __init__(self, params):
        self.params = params

    def get_param(self, name, default=None):
        return self.params.get(name, default)


@pytest.mark.parametrize("params,text", [
    ({"~port": "8880"}, "parameter port = '8880'"),
    ({"~port": True}, "parameter port = True"),
    ({"~obstacle_duration": float("nan")}, "parameter obstacle_duration = nan"),
    ({"~obstacle_duration": "long"}, "parameter obstacle_duration = 'long'"),
    ({"~obstacle_duration": True}, "parameter obstacle_duration = True"),
])
def test_bad_private_parameters_are_refused_naming_them(params, text):
    with pytest.raises(ValueError, match=text.replace(".", r"\.")):
        node.settings(node.parse_args([]), FakeRospy(params))


def test_good_parameters_are_taken_and_a_duration_rounds_up():
    conf = node.settings(node.parse_args(["--port", "0"]), FakeRospy({"~obstacle_duration": 1.2}))
    assert conf["port"] == 0 and conf["obstacle_duration"] == 2
    conf = node.settings(node.parse_args(["--host", "0.0.0.0", "--insecure"]), None)
    assert conf["host"] == "0.0.0.0"


def test_a_flag_that_is_not_a_number_stops_with_usage_naming_it(capsys):
    with pytest.raises(SystemExit) as stop:
        node.parse_args(["--port", "eighty"])
    assert stop.value.code == 2 and "--port: invalid int value: 'eighty'" in capsys.readouterr().err


def test_without_ros_a_broker_url_is_needed():
    with pytest.raises(ValueError, match="--broker-url is needed without ROS"):
        node.wait_broker_url(node.settings(node.parse_args([]), None), None)


def test_a_tls_broker_url_or_a_bad_one_stops_the_node_with_a_message(capsys):
    assert node.main(["--no-ros", "--broker-url", "mqtts://127.0.0.1:8883"]) == 2
    assert "plain loopback listener" in capsys.readouterr().err
    assert node.main(["--no-ros", "--broker-url", "http://nowhere"]) == 2
    assert capsys.readouterr().err.startswith("fleet_console: ")


@pytest.mark.parametrize("kind", ["not yaml", "unreadable image", "huge image"])
def test_the_console_with_a_bad_map_file_runs_and_says_why(tmp_path, kind):
    """The node itself (no ROS): a bad --map-file is reported in /config.json (the page shows it above the map),
    and the console serves the page and stops cleanly on SIGTERM."""
    import os
    import re
    import signal
    import subprocess
    import sys
    from test_mapimage import huge_png
    (tmp_path / "map.yaml").write_text({"not yaml": "image: [unclosed\n"}.get(
        kind, "image: map.png\nresolution: 0.05\norigin: [0, 0, 0]\n"))
    (tmp_path / "map.png").write_bytes(huge_png(30000, 30000) if kind == "huge image" else b"not a png")
    proc = subprocess.Popen([sys.executable, "-c", "from fleet_console.node import main; raise SystemExit(main())",
                             "--no-ros", "--port", "0", "--broker-url", "mqtt://127.0.0.1:%d" % closed_port(),
                             "--map-file", str(tmp_path / "map.yaml")], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    try:
        lines = []
        for line in proc.stdout:
            lines.append(line)
            found = re.search(r"point a browser at http://127\.0\.0\.1:(\d+)/", line)
            if found:
                break
        assert found, "".join(lines)
        server = SimpleNamespace(port=int(found.group(1)))
        config = json.loads(get(server, "/config.json")[1])
        assert config["map"] is None and config["mapError"].startswith("map file %s" % (tmp_path / "map.yaml"))
        assert {"not yaml": "is not YAML", "unreadable image": "image map.png cannot be read",
                "huge image": "decompression bomb"}[kind] in config["mapError"], config["mapError"]
        assert get(server, "/")[0] == 200 and get(server, "/map.png")[0] == 404
        assert "the console runs without a map" in "".join(lines)
        os.kill(proc.pid, signal.SIGTERM)
        assert proc.wait(20) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_the_readmes_parameter_table_gives_every_parameter_and_its_default():
    """fleet_console/README.md's table: each row's names (`~a` / `~b` or `~a`, `~b`) and defaults, in that order,
    are the node's DEFAULTS (credentials_dir "" means $ROS_HOME/fleet_security; broker_wait is named in a row)."""
    import os
    import re
    readme = open(os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "README.md")).read()
    documented = {}
    for names, defaults in re.findall(r"^\| ((?:`~\w+`(?:, | / )?)+) \| ([^|]+) \|", readme, flags=re.M):
        names = re.findall(r"`~(\w+)`", names)
        values = [v.strip().strip("`") for v in re.split(r", | / ", defaults.strip())]
        assert len(names) == len(values), (names, values)
        documented.update(zip(names, values))
    expected = {name: ("false" if value is False else '""' if value == "" else str(value))
                for name, value in node.DEFAULTS.items()}
    expected["credentials_dir"] = "$ROS_HOME/fleet_security"
    assert "`~broker_wait` (%g s)" % node.DEFAULTS["broker_wait"] in readme
    del expected["broker_wait"]
    assert documented == expected
