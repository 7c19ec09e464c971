"""End-to-end liveness over the bus (issue 27, attack 6): a TCP connection that is open and an
MQTT session that paho calls connected say nothing about whether messages flow. A silent 30 s
stall (robot_2 missed 72 of 89 deliveries) was reported "connected" throughout.

Two kinds of Coaty Channel events, which Coaty agents that do not observe these channels never see
(issue 29: the first design, a 1 s heartbeat from every robot to every robot listing all robots
heard, cost each robot 2.75 MB per minute at 100 robots):

- an **echo** at most each ``heartbeat_interval`` s on ``coaty/3/<ns>.echo/CHN:org.fleetsharing.Echo/<own
  sourceId>``, which only its sender subscribes to (that exact topic; its own namespace, so that a
  wildcard subscription of the fleet's namespace does not catch it): a minimal CoatyObject with a
  sequence number.
  Peers never receive it, so it costs each robot only its own ~150 bytes per interval, at most;
- a **peer heartbeat** on ``CHN:org.fleetsharing.Heartbeat/<sourceId>``, which every bridge
  observes, each ``peer_interval`` s: by default ``AUTO_SECONDS_PER_PEER`` s per peer known
  (floor: ``heartbeat_interval``), so what each robot receives of them stays about the same however
  large the fleet. It carries its sender's ``interval`` (the longest it waits until its next one),
  ``heard`` (how many peers it hears) and ``misses`` (the robots it expects, i.e. heard before or
  in known_robots, but has not heard for their timeout). A peer heartbeat counts as an echo too.

Each bridge checks:

- **own echo**: its newest echo or peer heartbeat came back within ``liveness_timeout`` s of being
  sent; otherwise the path to or from the broker is stalled (ERROR). An echo is not sent at a tick
  when everything up to the last one is back (``next_heartbeat`` says so): the tick still counts,
  and whatever is sent next (an obstacle update or advert coming back in our own areas, or the next
  tick's echo) must be back within ``liveness_timeout`` of that tick. A stall is found as soon as
  before; an idle robot echoes every other tick, and one whose own messages come back each tick
  echoes none;
- **peers**: every peer heard before (or named in ``known_robots``) was heard within
  ``peer_timeout(its announced interval)`` = max(liveness_timeout, PEER_TIMEOUT_INTERVALS x
  interval); otherwise it is partitioned from us or down without a leaving heartbeat (WARN). A
  robot in known_robots never heard is missed after that time for our own interval;
- **deaf peers**: a peer whose heartbeats arrive but whose ``misses`` name us does not receive us
  (WARN). Older heartbeats (``hears``: every robot heard, no ``interval``) are still accepted: their
  sender is judged by LEGACY_INTERVAL and is deaf when ``hears`` lacks us.

Pure Python, no paho; the clock is injected (tests advance it, nothing sleeps).
"""
import collections
import json
import random
import threading

OK, WARN, ERROR = 0, 1, 2
CHANNEL = "org.fleetsharing.Heartbeat"
OBJECT_TYPE = "org.fleetsharing.Heartbeat"
ECHO_CHANNEL = "org.fleetsharing.Echo"
ECHO_OBJECT_TYPE = "org.fleetsharing.Echo"

# automatic peer heartbeat interval (peer_heartbeat_interval 0): this many s per peer known. Each
# robot then receives about one peer heartbeat per 0.9 x AUTO_SECONDS_PER_PEER s (~220 bytes each:
# ~4.9 kB/min) at any fleet size; with the echo (an idle robot's every other 1 s tick: ~4.3 kB/min) below the
# 15 kB/min budget.
AUTO_SECONDS_PER_PEER = 3.0
# the next peer heartbeat goes out after a random JITTER..1 of the interval (which is announced as
# the longest wait): robots that started or reconnected together do not stay in step
JITTER = 0.8
# a peer is missed when silent for this many of its announced intervals (two lost in a row are not
# a partition), and never sooner than liveness_timeout
PEER_TIMEOUT_INTERVALS = 3
# senders of the first design did not announce an interval: they beat each 1 s (the default)
LEGACY_INTERVAL = 1.0
# an announced interval outside this range is refused (out_of_range)
MIN_ANNOUNCED_INTERVAL, MAX_ANNOUNCED_INTERVAL = 0.01, 3600.0
# s a bridge listens before its first peer heartbeat (a random 0.5..1 of it): peers beat about every
# AUTO_SECONDS_PER_PEER s in aggregate, so a robot joining a running fleet has heard how large it is
# (their ``heard`` counts) and announces a fitting interval at once, instead of beating each second to
# every robot until it has heard them all (1,000 robots joining: 10^6 deliveries a second)
LISTEN_BEFORE_FIRST = 2 * AUTO_SECONDS_PER_PEER
MAX_AUTO_INTERVAL = 3600.0
# names sent in misses at most (a big partition: the rest is not named); a received list longer than
# MAX_LIST is refused
MAX_MISSES_SENT = 200
MAX_LIST = 1000
# peers tracked at most (names from unauthenticated senders must not grow memory without bound)
MAX_PEERS = 10000
# own messages (other than heartbeats) remembered until they come back: the oldest are forgotten
# first (those the broker does not send back to us at all, e.g. a Resolve to somebody's Discover)
MAX_OWN_AWAITED = 256


def echo_namespace(namespace):
    """The Coaty namespace of the echoes of a fleet in ``namespace``: nobody observes it."""
    return namespace + ".echo"


def _compact(obj):
    return json.dumps({"object": obj}, separators=(",", ":"), allow_nan=False).encode()


def echo_payload(identity_id, seq):
    """The echo: a minimal CoatyObject (its name is empty: nobody but its sender reads it)."""
    return _compact({"objectType": ECHO_OBJECT_TYPE, "coreType": "CoatyObject", "objectId": identity_id,
                     "name": "", "seq": seq})


def heartbeat_payload(identity_id, robot, seq, peer, leaving=False):
    """A peer heartbeat; ``peer`` is the dict of Liveness.next_heartbeat (interval, heard, misses)."""
    obj = {"objectType": OBJECT_TYPE, "coreType": "CoatyObject", "objectId": identity_id, "name": robot,
           "robot": robot, "seq": seq, "interval": peer["interval"], "heard": peer["heard"]}
    if peer["misses"]:
        obj["misses"] = peer["misses"]
    if leaving:
        obj["leaving"] = True
    return _compact(obj)


def peer_timeout(interval, timeout):
    return max(float(timeout), PEER_TIMEOUT_INTERVALS * interval)


def _round_interval(value):
    # announced as a short number: 247.5, not 247.49999999
    return round(value, 2) if value < 10 else round(value, 1)


class Liveness:
    def __init__(self, robot, clock, timeout=3.0, known_robots=(), heartbeat_interval=1.0, peer_interval=0.0,
                 rng=None):
        self.robot = robot
        self.timeout = float(timeout)
        self.heartbeat_interval = float(heartbeat_interval)
        self.fixed_peer_interval = float(peer_interval)   # 0: automatic
        self._clock = clock
        self._lock = threading.Lock()
        self._started = clock()
        self._seq = 0
        self._sent = {}            # seq -> time sent (the last few)
        self._last_sent = None
        self._last_echo = None     # time the newest echo (or other own message) came back
        self._echoed_seq = 0
        self._skipped_at = None    # a tick whose echo was not sent, until something sent since is back
        self._awaited = collections.OrderedDict()   # (topic, payload) of own messages -> time sent
        self._rng = rng or random.Random()
        # time the next peer heartbeat is due (None: now); the first after listening (automatic interval)
        self._next_peer = None if self.fixed_peer_interval > 0 else \
            self._started + LISTEN_BEFORE_FIRST * self._rng.uniform(0.5, 1.0)
        self._interval = None      # the interval announced in the last one
        # robot -> (time heard, announced interval, misses us, heard count)
        self._peers = {}
        # robots whose identity the broker withdrew (a clean stop or its last will) since they were last heard
        self._departed = set()
        self._expected = set(r for r in known_robots if r != robot)

    # ----------------------------------------------------------- sending

    def peer_interval(self):
        """s until our next peer heartbeat: fixed, or AUTO_SECONDS_PER_PEER per peer known."""
        with self._lock:
            return self._peer_interval_locked()

    def _peer_interval_locked(self):
        if self.fixed_peer_interval > 0:
            return self.fixed_peer_interval
        # the fleet as we know it, or as large as a peer says it hears (a newcomer learns it from one heartbeat)
        announced = max((h for _t, _i, _m, h in self._peers.values() if isinstance(h, int)), default=0)
        known = max(len(set(self._peers) | self._expected), min(announced, MAX_PEERS))
        return _round_interval(min(MAX_AUTO_INTERVAL, max(self.heartbeat_interval, AUTO_SECONDS_PER_PEER * known)))

    def next_heartbeat(self, peer=None):
        """(seq, fields): the sequence number of the heartbeat about to be sent and, when a peer
        heartbeat is due (or ``peer`` is True), its fields {interval, heard, misses}; None: an echo
        only. A peer heartbeat is due from half an echo interval before its time on (the sender
        wakes once per heartbeat_interval)."""
        now = self._clock()
        with self._lock:
            if peer is None:
                peer = self._next_peer is None or now >= self._next_peer - 0.5 * self.heartbeat_interval
            if not peer and self._skipped_at is None and self._last_echo is not None \
                    and self._echoed_seq == self._seq:
                # everything sent so far is back: this tick needs no echo of its own. Whatever is
                # sent next proves it (status() judges the tick as if its echo had gone out)
                self._skipped_at = now
                return None, None
            self._seq += 1
            self._sent[self._seq] = now
            for old in [s for s in self._sent if s < self._seq - 64]:
                del self._sent[old]
            self._last_sent = now
            if not peer:
                return self._seq, None
            self._interval = self._peer_interval_locked()
            self._next_peer = now + self._interval * self._rng.uniform(JITTER, 1.0)
            heard = 0
            misses = []
            for robot in sorted(set(self._peers) | self._expected):
                entry = self._peers.get(robot)
                if entry is not None and now - entry[0] <= peer_timeout(entry[1], self.timeout):
                    heard += 1
                elif entry is not None or now - self._started > self._never_heard_after():
                    misses.append(robot)
            return self._seq, {"interval": self._interval, "heard": heard, "misses": misses[:MAX_MISSES_SENT]}

    def _never_heard_after(self):
        # a robot in known_robots we never heard: judged as if it beat at our own interval
        return peer_timeout(self._interval or self._peer_interval_locked(), self.timeout)

    # ----------------------------------------------------------- receiving

    def own_echo(self, seq):
        now = self._clock()
        with self._lock:
            if seq in self._sent and seq > self._echoed_seq:
                self._echoed_seq = seq
                self._back(self._sent[seq], now)

    def own_sent(self, topic, payload):
        """An own message other than a heartbeat went out: when it comes back (own_returned), it
        proves the path as an echo does. A repeat keeps the first time sent: the copy that comes
        back first must not vouch for a later send."""
        now = self._clock()
        with self._lock:
            self._awaited.setdefault((topic, payload), now)
            while len(self._awaited) > MAX_OWN_AWAITED:
                self._awaited.popitem(last=False)

    def own_returned(self, topic, payload):
        """An own message came back from the broker (in our own areas). True when it was awaited."""
        now = self._clock()
        with self._lock:
            sent = self._awaited.pop((topic, payload), None)
            if sent is None:
                return False
            self._back(sent, now)
            return True

    def _back(self, sent, now):
        # lock held: something sent at `sent` came back at `now`
        self._last_echo = now
        if self._skipped_at is not None and sent >= self._skipped_at:
            self._skipped_at = None

    def peer(self, robot, interval=LEGACY_INTERVAL, misses=(), heard=None, hears=None):
        """A peer's heartbeat: its announced interval and misses, or (a sender of the first design)
        ``hears``, the robots it heard."""
        if robot == self.robot:
            return
        misses_us = self.robot not in hears if hears is not None else self.robot in misses
        with self._lock:
            if robot not in self._peers and len(self._peers) >= MAX_PEERS:
                return
            self._peers[robot] = (self._clock(), float(interval), misses_us, heard)
            self._departed.discard(robot)

    def forget(self, robot):
        """A peer that said goodbye (leaving heartbeat) is not missed."""
        with self._lock:
            self._peers.pop(robot, None)
            self._departed.discard(robot)
            self._expected.discard(robot)

    def departed(self, robot):
        """The broker withdrew the peer's identity (its last will: the broker lost it). It is no longer
        counted alive until heard again; the partition verdict still follows its heartbeats."""
        with self._lock:
            if robot in self._peers:
                self._departed.add(robot)

    def alive(self, robot):
        """True when the peer was heard within its timeout and has not departed since."""
        now = self._clock()
        with self._lock:
            entry = self._peers.get(robot)
            return entry is not None and robot not in self._departed \
                and now - entry[0] <= peer_timeout(entry[1], self.timeout)

    def reset(self):
        """After a reconnect: the echo is judged from the next heartbeat on, and the next heartbeat
        is a peer heartbeat (peers that missed us hear us again at once)."""
        with self._lock:
            self._started = self._clock()
            self._last_echo = None
            self._next_peer = None
            self._skipped_at = None
            self._awaited.clear()

    # ----------------------------------------------------------- verdict

    def status(self):
        """(level, reason): OK / WARN / ERROR and why (empty when OK)."""
        now = self._clock()
        with self._lock:
            problems = []
            level = OK
            # the oldest heartbeat not echoed yet
            pending = [t for s, t in self._sent.items() if s > self._echoed_seq]
            if self._skipped_at is not None:
                pending.append(self._skipped_at)
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
                    if now - self._started > self._never_heard_after():
                        missing.append("%s never heard" % robot)
                elif now - heard[0] > peer_timeout(heard[1], self.timeout):
                    missing.append("%s silent for %.1f s (beats every %g s)" % (robot, now - heard[0], heard[1]))
            if missing:
                level = max(level, WARN)
                problems.append("partition: no heartbeat from " + ", ".join(missing))
            echo_ok = self._last_echo is not None and now - self._started > self.timeout and level != ERROR
            deaf = sorted(r for r, (t, interval, misses_us, _n) in self._peers.items()
                          if echo_ok and misses_us and now - t <= peer_timeout(interval, self.timeout))
            if deaf:
                level = max(level, WARN)
                problems.append("deaf receiver: %s does not hear us" % ", ".join(deaf))
            return level, "; ".join(problems)

    def values(self):
        now = self._clock()
        with self._lock:
            out = {"heartbeats_sent": self._seq, "heartbeats_echoed": self._echoed_seq,
                   "peers_heard": sum(1 for t, interval, _m, _n in self._peers.values()
                                      if now - t <= peer_timeout(interval, self.timeout)),
                   "peer_heartbeat_interval": self._interval or self._peer_interval_locked()}
            if self._last_echo is not None:
                out["own_echo_age"] = round(now - self._last_echo, 3)
            return out
