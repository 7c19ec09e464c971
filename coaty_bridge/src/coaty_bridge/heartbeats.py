"""End-to-end liveness on the wire (liveness.py has the rules): the bridge's echo and peer heartbeats out,
and the echoes and heartbeats it hears. A part of CoatyBridgeClient (client.py)."""
import logging

from coaty_bridge import codec
from coaty_bridge import liveness as liveness_rules
from coaty_bridge.errors import ForgedSourceError, OutOfRangeError, UnknownRobotError, WrongTypeError
from coaty_bridge.identity import identity_for
from coaty_bridge.liveness import OBJECT_TYPE as HEARTBEAT_OBJECT_TYPE
from coaty_bridge.topics import check_name

LOG = logging.getLogger("coaty_bridge.client")


class HeartbeatMixin:
    """Heartbeats of CoatyBridgeClient."""

    def _heartbeats(self):
        while not self._watch_stop.wait(self.config.heartbeat_interval):
            try:
                self.heartbeat()
            except Exception as err:  # noqa: BLE001 - keep beating
                LOG.error("%s: heartbeat failed: %s: %s", self.config.robot_name, type(err).__name__, err)

    def heartbeat(self, leaving=False):
        """Publishes one heartbeat, see liveness.py: the echo (a Channel event on a topic only we
        subscribe to) or, when due, the peer heartbeat every bridge observes (it is echoed too).
        ``leaving``: a last peer heartbeat of a clean stop, so that peers do not miss this robot."""
        if not self._connected:
            return None
        seq, peer = self.liveness.next_heartbeat(peer=True if leaving else None)
        if seq is None:
            self._count("echoes_skipped")   # all we sent is back; what we send next vouches for this tick
            return None
        if peer is None:
            self._send(self._echo_topic, liveness_rules.echo_payload(self.identity_id, seq), queue=False)
            self._count("echoes_sent")
            return None
        payload = liveness_rules.heartbeat_payload(self.identity_id, self.config.robot_name, seq, peer, leaving)
        if leaving:
            return self._mqtt.publish(self._heartbeat_topic, payload, qos=1)
        self._send(self._heartbeat_topic, payload, queue=False)
        self._count("peer_heartbeats_sent")
        return None

    def _on_echo(self, topic, payload):
        if topic.source_id != self.identity_id:
            self._count("ignored")   # somebody else's echo: we subscribe to our own only
            return
        data = codec.parse_payload(payload, self.config.limits)
        obj = data.get("object") if isinstance(data, dict) else None
        if not isinstance(obj, dict) or obj.get("objectType") != liveness_rules.ECHO_OBJECT_TYPE:
            raise WrongTypeError("echo without a %s object" % liveness_rules.ECHO_OBJECT_TYPE)
        seq = obj.get("seq")
        if isinstance(seq, bool) or not isinstance(seq, int):
            raise WrongTypeError("echo seq %r: wrong type" % (seq,))
        self.liveness.own_echo(seq)

    def _on_heartbeat(self, topic, payload):
        data = codec.parse_payload(payload, self.config.limits)
        obj = data.get("object") if isinstance(data, dict) else None
        if not isinstance(obj, dict) or obj.get("objectType") != HEARTBEAT_OBJECT_TYPE:
            raise WrongTypeError("heartbeat without a %s object" % HEARTBEAT_OBJECT_TYPE)
        robot, seq = obj.get("robot"), obj.get("seq")
        if not isinstance(robot, str) or isinstance(seq, bool) or not isinstance(seq, int):
            raise WrongTypeError("heartbeat fields robot %r, seq %r: wrong types" % (str(robot)[:40], seq))
        legacy = "interval" not in obj and "hears" in obj   # a sender of the first design (issue 27)
        if legacy:
            names, interval, heard = obj.get("hears"), liveness_rules.LEGACY_INTERVAL, None
        else:
            names, interval, heard = obj.get("misses", []), obj.get("interval"), obj.get("heard")
            if isinstance(interval, bool) or not isinstance(interval, (int, float)) \
                    or isinstance(heard, bool) or not isinstance(heard, int):
                raise WrongTypeError("heartbeat of %r: interval %r, heard %r: wrong types"
                                     % (str(robot)[:40], str(interval)[:20], str(heard)[:20]))
            if not liveness_rules.MIN_ANNOUNCED_INTERVAL <= interval <= liveness_rules.MAX_ANNOUNCED_INTERVAL \
                    or not 0 <= heard <= 10 ** 6:
                raise OutOfRangeError("heartbeat of %r: interval %r s not in %g..%g or heard %r not in 0..1000000"
                                      % (str(robot)[:40], interval, liveness_rules.MIN_ANNOUNCED_INTERVAL,
                                         liveness_rules.MAX_ANNOUNCED_INTERVAL, heard))
        if not isinstance(names, list) or not all(isinstance(h, str) for h in names):
            raise WrongTypeError("heartbeat of %r: %s must be a list of robot names"
                                 % (str(robot)[:40], "hears" if legacy else "misses"))
        if len(names) > liveness_rules.MAX_LIST:
            raise OutOfRangeError("heartbeat of %r: %s lists %d robots, more than %d"
                                  % (str(robot)[:40], "hears" if legacy else "misses", len(names),
                                     liveness_rules.MAX_LIST))
        check_name(robot, "heartbeat robot")
        self._note_robot_of(topic.source_id, robot)
        if topic.source_id == self.identity_id:
            self.liveness.own_echo(seq)   # our own peer heartbeat is an echo too
            return
        if self.config.authenticate_sources and topic.source_id != identity_for(self.config.namespace, robot):
            raise ForgedSourceError("heartbeat of %r was sent by %s" % (robot, topic.source_id))
        if self.config.known_robots and robot not in self.config.known_robots:
            raise UnknownRobotError("heartbeat of robot %r (sourceId %s): not in known_robots"
                                    % (robot, topic.source_id))
        if obj.get("leaving") is True:
            # a clean stop says so in a last heartbeat: not missed. (The Deadvertise does not tell:
            # the broker sends the same one as the last will of a robot it lost.)
            self.liveness.forget(robot)
            return
        if legacy:
            self.liveness.peer(robot, interval, hears=names)
            self._count("heartbeats_received_legacy")
        else:
            self.liveness.peer(robot, interval, misses=names, heard=heard)
        self._count("heartbeats_received")
