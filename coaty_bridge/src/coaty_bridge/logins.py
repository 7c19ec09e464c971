"""Who is logged in under a robot's login (issue 43, item 6). Imports neither paho nor rospy.

A robot's login proves who it is; a stolen one is a second connection under it. The broker no longer
makes the login the client id (a second connection then took the robot off the broker: 39 reconnects
in 20 s), so both stay connected, and the robot must be told instead:

- ``ConnectionLog`` reads mosquitto's log (``New client connected from <address> as <client id> (..., u'<login>')``
  and ``Client <client id> ...`` when it leaves) and, whenever a login has more than one connection, says
  so: a ``LoginAlert`` naming every client id connected under it and where the newest came from;
- run_broker publishes each alert on the robot's own channel (``CHN:fleet.logins.<identity>``), under the
  broker's own login (``fleet_broker``), which only it holds;
- ``LoginAlerts``, in the robot's bridge, keeps the alerts about other client ids than its own and says how
  bad it is for /diagnostics: WARN for one, ERROR for repeated ones (ALERTS_FOR_ERROR within ALERT_WINDOW s).
"""
import collections
import json
import re
from dataclasses import dataclass
from typing import Tuple

from coaty_bridge.errors import OutOfRangeError, WrongTypeError

#: The reserved robot name of run_broker's own login (it publishes the alerts).
BROKER_LOGIN_NAME = "fleet_broker"
#: The channel prefix of a robot's alerts: CHN:fleet.logins.<identity id>.
CHANNEL_PREFIX = "fleet.logins."
OBJECT_TYPE = "org.fleetsharing.LoginAlert"
#: s an alert keeps the robot's diagnostics WARN (or ERROR)
ALERT_WINDOW = 600.0
#: alerts within ALERT_WINDOW that make it an ERROR: repeated attempts
ALERTS_FOR_ERROR = 2
#: characters of a received alert's login, clientId, address and each client id, and client ids listed, at most
MAX_ALERT_TEXT = 256
MAX_ALERT_CLIENTS = 100

_CONNECTED = re.compile(r"New client connected from (?P<address>\S+) as (?P<client>\S+) \(.*\bu'(?P<login>[^']*)'\)")
_LEFT = re.compile(r"Client (?P<client>\S+) (?:disconnected|closed its connection|has exceeded timeout)")


def channel(identity_id):
    return CHANNEL_PREFIX + identity_id


@dataclass(frozen=True)
class LoginAlert:
    """More than one connection under ``login``: ``clients`` are the client ids connected under it now, the
    newest (``client_id``, from ``address``) last; ``stamp`` is the broker's log time."""
    login: str
    client_id: str
    address: str
    clients: Tuple[str, ...]
    stamp: float

    def payload(self, object_id):
        return json.dumps({"object": {
            "objectType": OBJECT_TYPE, "coreType": "CoatyObject", "objectId": object_id, "name": "login alert",
            "login": self.login, "clientId": self.client_id, "address": self.address, "clients": list(self.clients),
            "stamp": self.stamp}}, separators=(",", ":")).encode("utf-8")

    @classmethod
    def from_payload(cls, data):
        obj = data.get("object") if isinstance(data, dict) else None
        if not isinstance(obj, dict) or obj.get("objectType") != OBJECT_TYPE:
            raise WrongTypeError("login alert without a %s object" % OBJECT_TYPE)
        fields = [obj.get(k) for k in ("login", "clientId", "address", "clients", "stamp")]
        login, client_id, address, clients, stamp = fields
        if not all(isinstance(v, str) and 0 < len(v) <= MAX_ALERT_TEXT for v in (login, client_id, address)) \
                or not isinstance(clients, list) or not 1 <= len(clients) <= MAX_ALERT_CLIENTS \
                or not all(isinstance(c, str) and len(c) <= MAX_ALERT_TEXT for c in clients) \
                or isinstance(stamp, bool) or not isinstance(stamp, (int, float)):
            raise OutOfRangeError("login alert fields login, clientId, address, clients, stamp: wrong types or sizes")
        return cls(login, client_id, address, tuple(clients), float(stamp))


class ConnectionLog:
    """Follows mosquitto's log lines: who is connected under which login; ``line()`` returns a LoginAlert when
    a login gets a second (or further) connection. ``logins``: the logins worth alerting about (robots')."""

    def __init__(self, logins=()):
        self.logins = set(logins)
        self._by_client = {}                         # client id -> login
        self._clients = collections.defaultdict(list)   # login -> client ids, oldest first

    def line(self, text):
        stamp_text, _, rest = text.partition(": ")
        try:
            stamp = float(stamp_text)
        except ValueError:
            stamp = 0.0
        joined = _CONNECTED.search(rest)
        if joined:
            login, client = joined.group("login"), joined.group("client")
            self._leave(client)    # a client id connecting again replaces its earlier connection
            self._by_client[client] = login
            self._clients[login].append(client)
            if login in self.logins and len(self._clients[login]) > 1:
                return LoginAlert(login, client, joined.group("address"), tuple(self._clients[login]), stamp)
            return None
        left = _LEFT.search(rest)
        if left:
            self._leave(left.group("client"))
        return None

    def _leave(self, client):
        login = self._by_client.pop(client, None)
        if login is not None and client in self._clients[login]:
            self._clients[login].remove(client)
            if not self._clients[login]:
                del self._clients[login]


class LoginAlerts:
    """The alerts a robot's bridge got about its own login, for /diagnostics. ``own_client_id``: this bridge's
    (its own connection is in every alert's ``clients``)."""

    def __init__(self, robot, own_client_id, clock):
        self.robot, self.own_client_id, self._clock = robot, own_client_id, clock
        self._alerts = collections.deque(maxlen=100)   # (clock time, LoginAlert, other client ids)
        self.count = 0

    def note(self, alert):
        others = tuple(c for c in alert.clients if c != self.own_client_id)
        if not others:
            return None
        self._alerts.append((self._clock(), alert, others))
        self.count += 1
        return others

    def status(self):
        """(level, message): level 0 OK, 1 WARN (one alert within ALERT_WINDOW), 2 ERROR (repeated)."""
        now = self._clock()
        recent = [(t, a, o) for t, a, o in self._alerts if now - t <= ALERT_WINDOW]
        if not recent:
            return 0, ""
        _t, alert, others = recent[-1]
        prefix = self.own_client_id[:13]
        guess = " (one of them looks like this robot's bridge before a restart)" if any(
            o.startswith(prefix) for o in others) else ""
        text = ("%d other connection(s) under %s's login in the last %.0f s, latest from %s as %s%s; if they are not "
                "this robot, its secret has leaked: rotate it (rosrun coaty_bridge fleet_credentials rotate %s)"
                % (len(recent), self.robot, ALERT_WINDOW, alert.address, ", ".join(others), guess, self.robot))
        return (2 if len(recent) >= ALERTS_FOR_ERROR else 1), text
