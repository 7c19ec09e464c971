"""Fair delivery (issue 27, item 3): one queue per sender, served round-robin. Pure Python.

Used by the Coaty bridge (per MQTT sourceId, between paho's thread and its worker).

paho reads every MQTT message in the order the broker sent them, one thread. When the work
behind a message (JSON, index decoding, the handler) is done in that thread, 5,000 messages of
one flooding peer sit in front of every other robot's obstacle. So the MQTT thread only sorts
raw messages into a queue per sourceId (cheap), and one worker takes them one source at a time
in turn: a message of another source waits for at most one message of each busy source, whatever
the length of the flood's queue. A full per-source queue drops that source's newest message
(counted): the flood loses, nobody else does.
"""
import collections
import threading


class FairQueue:
    """Per-key FIFO queues served round-robin. Thread-safe; ``get`` blocks."""

    def __init__(self, max_per_key, max_keys=4096):
        if isinstance(max_per_key, bool) or not isinstance(max_per_key, int) or max_per_key < 1:
            raise ValueError("max_per_key %r must be an integer >= 1" % (max_per_key,))
        self.max_per_key = max_per_key
        self.max_keys = max_keys
        self._queues = collections.OrderedDict()   # key -> deque; order = turn (next first)
        self._size = 0
        self._cond = threading.Condition()
        self._closed = False

    def __len__(self):
        return self._size

    def put(self, key, item):
        """Queues `item` behind `key`'s earlier ones; False (not queued) when that key's queue is
        full, or too many keys are waiting."""
        with self._cond:
            queue = self._queues.get(key)
            if queue is None:
                if len(self._queues) >= self.max_keys:
                    return False
                queue = self._queues[key] = collections.deque()   # a new key's turn is last
            elif len(queue) >= self.max_per_key:
                return False
            queue.append(item)
            self._size += 1
            self._cond.notify()
            return True

    def pop(self):
        """The next (key, item) in round-robin order, or None when empty (does not block)."""
        with self._cond:
            return self._pop()

    def _pop(self):
        if not self._queues:
            return None
        key, queue = next(iter(self._queues.items()))
        item = queue.popleft()
        self._size -= 1
        if queue:
            self._queues.move_to_end(key)   # its next message waits for one of every other key
        else:
            del self._queues[key]
        return key, item

    def get(self, timeout=None):
        """Like pop, but waits up to `timeout` s (None: until an item or close()); None when none."""
        with self._cond:
            if not self._queues and not self._closed:
                self._cond.wait(timeout)
            return self._pop()

    def close(self):
        with self._cond:
            self._closed = True
            self._cond.notify_all()
