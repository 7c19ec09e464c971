"""End-to-end liveness over the bus (issue 27, attack 6): a TCP connection that is open and an
MQTT session that paho calls connected say nothing about whether messages flow. A silent 30 s
stall (robot_2 missed 72 of 89 deliveries) was reported "connected" throughout.

Every bridge publishes a small heartbeat each ``heartbeat_interval`` s: a Coaty Channel event on
channel ``<namespace-wide heartbeat channel>`` (``CHN:org.fleetsharing.Heartbeat``), which Coaty
agents that do not observe that channel never see. It carries the robot's name, a sequence
number and the robots whose heartbeats it currently hears. The broker sends it back to its sender
too (we subscribe to the channel), so each bridge checks:

- **own echo**: its own latest heartbeat came back within ``liveness_timeout`` s of being sent;
  otherwise the path to or from the broker is stalled (ERROR);
- **peers**: every peer heard before (or named in ``known_robots``) was heard within
  ``liveness_timeout`` s; otherwise it is partitioned from us or down without a Deadvertise (WARN);
- **deaf peers**: a peer whose heartbeats arrive but do not list us does not receive (WARN).

Pure Python, no paho; the clock is injected (tests advance it, nothing sleeps).
"""
import threading

OK, WARN, ERROR = 0, 1, 2
CHANNEL = "org.fleetsharing.Heartbeat"
OBJECT_TYPE = "org.fleetsharing.Heartbeat"


class Liveness:
    def __init__(self, robot, clock, timeout=3.0, known_robots=()):
        self.robot = robot
        self.timeout = float(timeout)
        self._clock = clock
        self._lock = threading.Lock()
        self._started = clock()
        self._seq = 0
        self._sent = {}            # seq -> time sent (the last few)
        self._last_sent = None
        self._last_echo = None     # time the newest echo arrived
        self._echoed_seq = 0
        self._peers = {}           # robot -> (time heard, robots it hears)
        self._expected = set(r for r in known_robots if r != robot)

    # ----------------------------------------------------------- events

    def next_heartbeat(self):
        """Sequence number and the robots heard now, for the heartbeat about to be sent."""
        now = self._clock()
        with self._lock:
            self._seq += 1
            self._sent[self._seq] = now
            for old in [s for s in self._sent if s < self._seq - 64]:
                del self._sent[old]
            self._last_sent = now
            hears = sorted(r for r, (t, _h) in self._peers.items() if now - t <= self.timeout)
            return self._seq, hears

    def own_echo(self, seq):
        now = self._clock()
        with self._lock:
            if seq in self._sent and seq > self._echoed_seq:
                self._echoed_seq = seq
                self._last_echo = now

    def peer(self, robot, hears):
        if robot == self.robot:
            return
        with self._lock:
            self._peers[robot] = (self._clock(), frozenset(hears))

    def forget(self, robot):
        """A peer that said goodbye (Deadvertise) is not missed."""
        with self._lock:
            self._peers.pop(robot, None)
            self._expected.discard(robot)

    def reset(self):
        """After a reconnect: the echo is judged from the next heartbeat on."""
        with self._lock:
            self._started = self._clock()
            self._last_echo = None

    # ----------------------------------------------------------- verdict

    def status(self):
        """(level, reason): OK / WARN / ERROR and why (empty when OK)."""
        now = self._clock()
        with self._lock:
            problems = []
            level = OK
            # the oldest heartbeat not echoed yet
            pending = [t for s, t in self._sent.items() if s > self._echoed_seq]
            if pending and now - min(pending) > self.timeout:
                level = ERROR
                since = "never" if self._last_echo is None else "%.1f s ago" % (now - self._last_echo)
                problems.append("stalled: own heartbeat not echoed by the broker for %.1f s (last echo %s)"
                                % (now - min(pending), since))
            elif self._last_sent is None and now - self._started > self.timeout:
                level = ERROR
                problems.append("no heartbeat sent for %.1f s" % (now - self._started))
            missing = []
            for robot in sorted(set(self._peers) | self._expected):
                heard = self._peers.get(robot)
                if heard is None:
                    if now - self._started > self.timeout:
                        missing.append("%s never heard" % robot)
                elif now - heard[0] > self.timeout:
                    missing.append("%s silent for %.1f s" % (robot, now - heard[0]))
            if missing:
                level = max(level, WARN)
                problems.append("partition: no heartbeat from " + ", ".join(missing))
            deaf = sorted(r for r, (t, hears) in self._peers.items()
                          if now - t <= self.timeout and self._last_echo is not None
                          and now - self._started > self.timeout and self.robot not in hears)
            if deaf:
                level = max(level, WARN)
                problems.append("deaf receiver: %s does not hear us" % ", ".join(deaf))
            return level, "; ".join(problems)

    def values(self):
        now = self._clock()
        with self._lock:
            out = {"heartbeats_sent": self._seq, "heartbeats_echoed": self._echoed_seq,
                   "peers_heard": sum(1 for t, _h in self._peers.values() if now - t <= self.timeout)}
            if self._last_echo is not None:
                out["own_echo_age"] = round(now - self._last_echo, 3)
            return out
