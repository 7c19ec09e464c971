"""Reads a bag in timestamp order and keeps going past damage, counting what was lost.

- An unindexed bag (a recorder that was killed, or a truncated file) or one whose index cannot
  be parsed is reindexed in a temporary copy (rosbag's own reindex, as ``rosbag reindex``
  does); the original is never written. What reindexing could not recover is lost and
  reported. A bag with no readable message at all is a BagOpenError.
- Messages are read raw and deserialised here, one by one, so a message whose bytes do not
  parse is counted (``bad_message``) and skipped instead of ending the read.
- A chunk that cannot be read (bad compression, bad record header) ends rosbag's generator;
  the reader resumes after that chunk's time range and counts the messages of the selected
  topics that the index says were there (``lost_messages``).
"""
import logging
import os
import shutil
import tempfile

import rosbag
import rospy

from sharing_replay.errors import BagOpenError

LOG = logging.getLogger(__name__)


class BagSource:
    """One bag, opened for reading (possibly through a reindexed temporary copy)."""

    def __init__(self, path):
        self.path = path
        self.problems = {}           # counter name -> count
        self.notes = []              # one line per problem, for the report
        self._tmpdir = None
        if not os.path.isfile(path):
            raise BagOpenError("bag %s does not exist" % path)
        try:
            self.bag = rosbag.Bag(path, "r")
        except rosbag.ROSBagUnindexedException:
            self.bag = self._reindexed_copy(path, "has no index (truncated or not closed)")
        except OSError as err:
            raise BagOpenError("bag %s cannot be opened: %s" % (path, err)) from None
        except Exception as err:  # noqa: BLE001 - rosbag's parser raises struct.error & co. on garbage
            # A damaged index (the end of the file): the chunks may still be readable.
            self.bag = self._reindexed_copy(path, "has a damaged index (%s: %s)" % (type(err).__name__,
                                                                                   str(err)[:80]))
        if not self.bag._chunks or not self.bag.get_message_count():
            why = " (%s)" % self.notes[0] if self.notes else ""
            self.close()
            raise BagOpenError("bag %s holds no message%s" % (path, why))

    def _count(self, name, n=1, note=None):
        self.problems[name] = self.problems.get(name, 0) + n
        if note:
            self.notes.append(note)
            LOG.warning("%s", note)

    def _reindexed_copy(self, path, why):
        self._tmpdir = tempfile.mkdtemp(prefix="replay_reindex_")
        copy = os.path.join(self._tmpdir, os.path.basename(path))
        shutil.copyfile(path, copy)
        try:
            bag = rosbag.Bag(copy, "a", allow_unindexed=True)
            for _ in bag.reindex():
                pass
            bag.close()
            bag = rosbag.Bag(copy, "r")
        except Exception as err:  # noqa: BLE001 - anything rosbag raises means: not recoverable
            self.close()
            raise BagOpenError("bag %s %s and cannot be reindexed (%s: %s)"
                               % (path, why, type(err).__name__, str(err)[:120])) from None
        self._count("bag_unindexed", note="bag %s %s: replaying a reindexed copy; messages after the "
                    "last complete chunk are lost" % (path, why))
        return bag

    def close(self):
        try:
            if getattr(self, "bag", None) is not None:
                self.bag.close()
        finally:
            if self._tmpdir:
                shutil.rmtree(self._tmpdir, ignore_errors=True)
                self._tmpdir = None

    # --- what is in it ----------------------------------------------------------------------
    def topics(self):
        """{topic: (msg_type, message_count)}."""
        info = self.bag.get_type_and_topic_info()
        return {t: (i.msg_type, i.message_count) for t, i in info.topics.items()}

    @property
    def start_time(self):
        return self.bag.get_start_time()

    @property
    def end_time(self):
        return self.bag.get_end_time()

    def _indexed_between(self, topics, after, until):
        """Messages of `topics` the index places in (after, until] (rospy.Time bounds; after may be None)."""
        count = 0
        for conn_id, conn in self.bag._connections.items():
            if conn.topic not in topics:
                continue
            for entry in self.bag._connection_indexes.get(conn_id, ()):
                if (after is None or entry.time > after) and entry.time <= until:
                    count += 1
        return count

    def _chunk_end_after(self, t):
        """End time (rospy.Time) of the first chunk that ends after t (None: any), or None."""
        ends = sorted(c.end_time for c in self.bag._chunks if t is None or c.end_time > t)
        return ends[0] if ends else None

    # --- reading ----------------------------------------------------------------------------
    def messages(self, topics, numpy_topics=()):
        """Yields (topic, msg, t_seconds) in bag order; damaged parts are skipped and counted.
        Messages of `numpy_topics` are deserialised with NumPy arrays (genpy's deserialize_numpy)."""
        import numpy
        topics = list(topics)
        numpy_topics = set(numpy_topics)
        wanted = set(topics)
        start = None
        last = None          # rospy.Time of the last message read (exact, to resume after it)
        last_t = float("-inf")
        while True:
            try:
                gen = self.bag.read_messages(topics=topics, start_time=start, raw=True)
                for topic, raw, t in gen:
                    last = t
                    last_t = t.to_sec()
                    datatype, data, _md5, _pos, pytype = raw
                    try:
                        msg = pytype()
                        if topic in numpy_topics:
                            msg.deserialize_numpy(data, numpy)
                        else:
                            msg.deserialize(data)
                    except Exception as err:  # noqa: BLE001 - genpy raises many types on bad bytes
                        self._count("bad_message", note="%s at %.3f: a %s that does not deserialise (%s: %s)"
                                    % (topic, last_t, datatype, type(err).__name__, str(err)[:80]))
                        continue
                    yield topic, msg, last_t
                return
            except GeneratorExit:
                raise
            except Exception as err:  # noqa: BLE001 - rosbag/roslz4/bz2 raise many types on damage
                resume = self._chunk_end_after(last)
                if resume is None:
                    self._count("damaged_chunks", note="bag %s: unreadable data after %.3f s (%s: %s); "
                                "nothing readable follows" % (self.path, last_t, type(err).__name__,
                                                              str(err)[:100]))
                    return
                lost = self._indexed_between(wanted, last, resume)
                self._count("damaged_chunks", note="bag %s: unreadable chunk after %.3f s (%s: %s); "
                            "skipping to %.3f s, %d indexed message(s) of the replayed topics lost"
                            % (self.path, last_t, type(err).__name__, str(err)[:100], resume.to_sec(), lost))
                self._count("lost_messages", lost)
                start = resume + rospy.Duration(0, 1)
                last = resume
                last_t = resume.to_sec()
