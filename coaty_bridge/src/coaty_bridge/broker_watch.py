"""What run_broker does while the fleet runs (issue 43): keeps mosquitto up, takes logins added or rotated
in the credentials folder without a restart, and tells a robot about other connections under its login.
Imports paho (the alerts go over MQTT); no rospy.

- ``BrokerKeeper.tick()``: mosquitto died -> started again on the same port with the same logins (bridges
  reconnect to the URL they have; their handlers keep the fleet's obstacles, and each bridge asks its
  peers again on reconnecting);
- ``CredentialsWatch.tick()``: a secret in the folder added or changed (``fleet_credentials add|rotate``) ->
  the password file and ACL written again and mosquitto reloads them (SIGHUP);
- ``LoginWatch.tick()``: new lines of mosquitto's log -> ``logins.ConnectionLog`` -> an alert published on the
  robot's own channel under run_broker's login (``fleet_broker``), which the robot's bridge shows in its
  /diagnostics.
Each ``tick`` is called about once a second by run_broker's loop and returns a line to log, or None.
"""
import os
import uuid as uuidlib

from coaty_bridge import logins
from coaty_bridge.connection import _make_paho_client
from coaty_bridge.identity import identity_for
from coaty_bridge.topics import Topic


class BrokerKeeper:
    """Restarts ``broker`` (a broker.Broker) when its mosquitto has died."""

    def __init__(self, broker):
        self.broker = broker
        self.restarts = 0

    def tick(self):
        if self.broker.running():
            return None
        self.broker.respawn()
        self.restarts += 1
        return "mosquitto had died; started again on %s (restart %d): bridges reconnect and ask their peers for " \
               "the fleet's obstacles" % (self.broker.url, self.restarts)


class CredentialsWatch:
    """Rewrites the broker's logins when the credentials folder changes and has mosquitto reload them."""

    def __init__(self, creds, broker):
        self.creds, self.broker = creds, broker
        self._seen = creds.fingerprint()
        self._robots = set(creds.robots_in_folder())

    def tick(self):
        try:
            now = self.creds.fingerprint()
        except (OSError, ValueError) as err:
            return "credentials folder %s unreadable (%s); logins unchanged" % (self.creds.directory, err)
        if now == self._seen:
            return None
        robots = set(self.creds.write_logins(self.broker.directory))
        before = dict(p for p in self._seen if isinstance(p, tuple))
        after = dict(p for p in now if isinstance(p, tuple))
        added = sorted(robots - self._robots)
        rotated = sorted(r for r in after if r in before and after[r] != before[r])
        self._seen, self._robots = now, robots
        self.broker.reload()
        return "logins reloaded without a restart: %s%s%s" % (
            "added %s" % " ".join(added) if added else "",
            "; " if added and rotated else "",
            "new secret for %s" % " ".join(rotated) if rotated else ("" if added else "a role's secret changed"))


class LoginWatch:
    """Follows mosquitto's log and publishes a login alert to the robot whose login has a second connection."""

    def __init__(self, creds, broker, namespace):
        self.creds, self.broker, self.namespace = creds, broker, namespace
        self.connections = logins.ConnectionLog(self._robot_logins())
        self._robot_of = {}
        self._offset = 0
        self._inode = None
        self._client = None
        self.alerts = 0
        self._source = identity_for(namespace, logins.BROKER_LOGIN_NAME)

    def _robot_logins(self):
        self._robot_of = {identity_for(self.namespace, r): r for r in self.creds.robots_in_folder()}
        return set(self._robot_of)

    def _connect(self):
        username, password = self.creds.broker_login()
        client = _make_paho_client("fleet_broker-" + uuidlib.uuid4().hex[:12])
        client.username_pw_set(username, password)
        client.reconnect_delay_set(0.5, 5.0)
        client.connect_async(self.broker.host, self.broker.port)
        client.loop_start()
        self._client = client

    def stop(self):
        if self._client is not None:
            self._client.disconnect()
            self._client.loop_stop()

    def _new_lines(self):
        path = self.broker.log_path
        try:
            stat = os.stat(path)
        except OSError:
            return []
        if stat.st_ino != self._inode or stat.st_size < self._offset:
            self._inode, self._offset = stat.st_ino, 0   # a new log (restarted, or truncated)
        with open(path, "rb") as log:
            log.seek(self._offset)
            data = log.read()
        complete = data.rfind(b"\n") + 1
        self._offset += complete
        return data[:complete].decode("utf-8", errors="replace").splitlines()

    def reset(self):
        """mosquitto started again: nobody is connected any more (its log says nothing of those it lost)."""
        self.connections = logins.ConnectionLog(self._robot_logins())

    def tick(self):
        if self._client is None:
            self._connect()
        self.connections.logins = self._robot_logins()
        out = []
        for line in self._new_lines():
            alert = self.connections.line(line)
            if alert is None:
                continue
            robot = self._robot_of.get(alert.login, alert.login)
            topic = str(Topic(self.namespace, "CHN", self._source, filter=logins.channel(alert.login)))
            self._client.publish(topic, alert.payload(str(uuidlib.uuid4())), qos=1)
            self.alerts += 1
            out.append("%d connections under %s's login now (%s); the latest from %s as %s: told %s"
                       % (len(alert.clients), robot, ", ".join(alert.clients), alert.address, alert.client_id, robot))
        return "; ".join(out) or None
