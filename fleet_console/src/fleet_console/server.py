"""The console's web server: the page, its scripts, the map, and MQTT over WebSockets to the fleet's broker.

One port (HTTP and WebSocket, python3-websockets). ``/mqtt`` is a WebSocket that carries the browser's MQTT
bytes to the broker's TCP listener and back, untouched: the browser logs in to mosquitto itself and the
broker's logins and ACL decide everything (Debian 12's mosquitto 2.0.11 is built without websockets, so the
broker cannot take the WebSocket itself). The server holds no login and publishes nothing: it cannot change an
obstacle, and the robots never wait on it (a slow or dead browser only fills its own socket's buffers).

No rospy here: the node (node.py) gives the map and the diagnostics in through ``ConsoleState``.
"""
import asyncio
import hmac
import http
import json
import logging
import mimetypes
import os
import threading
import time
from urllib.parse import parse_qs, urlsplit

import websockets
import websockets.legacy.server

from coaty_bridge.identity import identity_for
from coaty_bridge.security import read_password_file
from coaty_bridge.topics import check_name
from sharing_msgs.authority import OPERATOR_VERSION_MARGIN

LOG = logging.getLogger(__name__)
WEB_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "web")
#: the browser scripts scripts/setup.sh installs from the npm registry (package.json), served as /vendor/<name>
VENDOR = {"mqtt.min.js": os.path.join("node_modules", "mqtt", "dist", "mqtt.min.js")}
MAX_CONNECTIONS = 32


class ConsoleState:
    """What the server shows besides the bus: the map (or why there is none) and the fleet's /diagnostics."""

    def __init__(self):
        self._lock = threading.Lock()
        self.map, self.map_error, self.map_version = None, "no map yet (waiting for the fleet's map server)", 0
        self.diagnostics = {}

    def set_map(self, console_map=None, error=None):
        with self._lock:
            self.map, self.map_error = console_map, error
            self.map_version += 1

    def set_diagnostic(self, name, level, message, values, stamp=None):
        with self._lock:
            self.diagnostics[name] = {"name": name, "level": int(level), "message": message[:400],
                                      "values": dict(list(values.items())[:200]), "time": stamp or time.time()}

    def snapshot(self):
        with self._lock:
            return self.map, self.map_error, self.map_version, [dict(v) for v in self.diagnostics.values()]


class ConsoleServer:
    """Serves the console on host:port (port 0 = a free one) until stop()."""

    def __init__(self, broker_host, broker_port, state, namespace="fleet", object_type="org.fleetsharing.SharedObstacle",
                 host="127.0.0.1", port=0, credentials_dir="", obstacle_duration=1200, ssl_context=None,
                 package_dir=None, title="Fleet console"):
        self.broker = (broker_host, int(broker_port))
        self.state, self.namespace, self.object_type = state, namespace, object_type
        self.host, self.port, self.credentials_dir = host, int(port), credentials_dir
        self.obstacle_duration, self.ssl_context, self.title = obstacle_duration, ssl_context, title
        self.package_dir = package_dir or os.path.dirname(WEB_DIR)
        self.connections = 0
        self.counters = {"ws_connections": 0, "ws_refused": 0, "broker_unreachable": 0, "http_requests": 0}
        self._loop, self._server, self._thread = None, None, None
        self._started = threading.Event()

    # ------------------------------------------------------------------ life
    def start(self):
        self._thread = threading.Thread(target=self._run, name="fleet_console_http", daemon=True)
        self._thread.start()
        if not self._started.wait(15) or self._server is None:
            raise RuntimeError("fleet_console: could not listen on %s:%d: %s" % (self.host, self.port, self._error))
        return self

    _error = "timed out"

    def _run(self):
        self._loop = asyncio.new_event_loop()
        asyncio.set_event_loop(self._loop)
        try:
            self._server = self._loop.run_until_complete(websockets.legacy.server.serve(
                self._proxy, self.host, self.port, process_request=self._http, subprotocols=["mqtt", "mqttv3.1"],
                ssl=self.ssl_context, max_size=2 ** 21, compression=None, ping_interval=20, ping_timeout=20))
            self.port = self._server.sockets[0].getsockname()[1]
        except OSError as err:
            self._error = str(err)
            self._server = None
        self._started.set()
        if self._server is not None:
            self._loop.run_forever()

    def stop(self):
        if self._loop is None or self._server is None:
            return
        async def close():
            self._server.close()
            await self._server.wait_closed()
        asyncio.run_coroutine_threadsafe(close(), self._loop).result(10)
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(10)

    @property
    def url(self):
        host = "127.0.0.1" if self.host in ("", "0.0.0.0") else self.host
        return "%s://%s:%d/" % ("https" if self.ssl_context else "http", host, self.port)

    # ------------------------------------------------------------------ HTTP
    def _http(self, path, headers):
        parts = urlsplit(path)
        if parts.path == "/mqtt":
            if self.connections >= MAX_CONNECTIONS:
                self.counters["ws_refused"] += 1
                return self._text(http.HTTPStatus.SERVICE_UNAVAILABLE, "too many console connections\n")
            return None   # the WebSocket handshake goes on
        self.counters["http_requests"] += 1
        try:
            return self._route(parts.path, parse_qs(parts.query), headers)
        except Exception as err:   # a bad request never takes the server down
            LOG.warning("fleet_console: %s failed: %s: %s", parts.path[:80], type(err).__name__, err)
            return self._text(http.HTTPStatus.INTERNAL_SERVER_ERROR, "error: %s\n" % err)

    def _route(self, path, query, headers):
        if path in ("/", "/index.html"):
            return self._file(os.path.join(WEB_DIR, "index.html"))
        if path.startswith("/web/") and "/" not in path[5:] and not path[5:].startswith("."):
            return self._file(os.path.join(WEB_DIR, path[5:]))
        if path.startswith("/vendor/") and path[8:] in VENDOR:
            vendor = os.path.join(self.package_dir, VENDOR[path[8:]])
            if not os.path.exists(vendor):
                return self._text(http.HTTPStatus.NOT_FOUND, "%s is not installed: run scripts/setup.sh (npm install "
                                  "in fleet_console)\n" % path[8:])
            return self._file(vendor)
        console_map, map_error, map_version, _ = self.state.snapshot()
        if path == "/config.json":
            return self._json({"namespace": self.namespace, "objectType": self.object_type, "wsPath": "/mqtt",
                               "obstacleDuration": self.obstacle_duration, "title": self.title,
                               "versionMargin": OPERATOR_VERSION_MARGIN,
                               "map": dict(console_map.meta(), version=map_version) if console_map else None,
                               "mapError": map_error})
        if path == "/map.png":
            if console_map is None:
                return self._text(http.HTTPStatus.NOT_FOUND, "no map: %s\n" % map_error)
            return (http.HTTPStatus.OK, [("Content-Type", "image/png"), ("Cache-Control", "no-store")],
                    console_map.png)
        if path == "/identity":
            return self._identity(query)
        if path == "/health.json":
            return self._health(headers)
        return self._text(http.HTTPStatus.NOT_FOUND, "not found\n")

    def _identity(self, query):
        name = (query.get("name") or [""])[0]
        try:
            check_name(name, "login name")
        except ValueError as err:
            return self._json({"error": "login name %r: %s" % (name[:60], err)}, http.HTTPStatus.BAD_REQUEST)
        return self._json({"name": name, "identity": identity_for(self.namespace, name), "role": self._role(name)})

    def _role(self, name):
        """operator, viewer, or "" when the console does not know (another credentials folder)."""
        if not self.credentials_dir:
            return ""
        try:
            check_name(name, "login name")   # no '/': "../broker" must not reach the broker's own secret
        except ValueError:
            return ""
        for folder, role in (("operators", "operator"), ("viewers", "viewer")):
            if os.path.exists(os.path.join(self.credentials_dir, folder, name + ".password")):
                return role
        return ""

    def _health(self, headers):
        """The fleet's /diagnostics, only for a console login (its name and password, as on the broker)."""
        login = headers.get("X-Fleet-Login", "")
        name, _, password = login.partition(":")
        if not self._login_ok(name, password):
            return self._json({"error": "health needs a console login"}, http.HTTPStatus.FORBIDDEN)
        _, _, _, diagnostics = self.state.snapshot()
        return self._json({"diagnostics": sorted(diagnostics, key=lambda d: d["name"]), "server": dict(self.counters)})

    def _login_ok(self, name, password):
        role = self._role(name) if name else ""
        if not role or not password:
            return False
        try:
            secret = read_password_file(os.path.join(self.credentials_dir, role + "s", name + ".password"))
        except ValueError:
            return False
        return hmac.compare_digest(secret.encode(), password.encode())

    @staticmethod
    def _file(path):
        try:
            with open(path, "rb") as handle:
                body = handle.read()
        except OSError:
            return ConsoleServer._text(http.HTTPStatus.NOT_FOUND, "not found\n")
        kind = mimetypes.guess_type(path)[0] or "application/octet-stream"
        return http.HTTPStatus.OK, [("Content-Type", kind), ("Cache-Control", "no-store")], body

    @staticmethod
    def _json(value, status=http.HTTPStatus.OK):
        return status, [("Content-Type", "application/json"), ("Cache-Control", "no-store")], \
            json.dumps(value, allow_nan=False).encode()

    @staticmethod
    def _text(status, text):
        return status, [("Content-Type", "text/plain; charset=utf-8")], text.encode()

    # ------------------------------------------------------------------ MQTT over WebSocket
    async def _proxy(self, websocket, path=None):
        self.connections += 1
        self.counters["ws_connections"] += 1
        writer = None
        try:
            try:
                reader, writer = await asyncio.wait_for(asyncio.open_connection(*self.broker), 5)
            except (OSError, asyncio.TimeoutError) as err:
                self.counters["broker_unreachable"] += 1
                await websocket.close(1011, "the fleet's broker %s:%d cannot be reached: %s"
                                      % (self.broker[0], self.broker[1], err)[:120])
                return

            async def browser_to_broker():
                async for message in websocket:
                    writer.write(message if isinstance(message, bytes) else message.encode())
                    await writer.drain()

            async def broker_to_browser():
                while True:
                    data = await reader.read(65536)
                    if not data:
                        break
                    await websocket.send(data)
            tasks = [asyncio.ensure_future(browser_to_broker()), asyncio.ensure_future(broker_to_browser())]
            await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
            for task in tasks:
                task.cancel()
            await websocket.close()
        except websockets.ConnectionClosed:
            pass
        finally:
            self.connections -= 1
            if writer is not None:
                writer.close()
