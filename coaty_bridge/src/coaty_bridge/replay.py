"""Which of this robot's own updates of an obstacle a replay carries (Discover answers and area catch-up).
Imports neither paho nor rospy.

A bridge replays its own updates of live obstacles, as sent and aged, to a robot that joins, reconnects or enters
their area (README "Partitions and restarts"), so that marks and clears converge there as if it had never been
away. A receiver keeps per cell the greatest stamp (version, source) that touched it (sharing_handler_py.logic):
of two own updates touching one cell, the one with the greater version decides it, and what the other said of
that cell changes nothing. Replayed whole, the history grew with the obstacle's life: a robot watching a changing
obstacle through a 1,200 s lease, one update a minute, replayed 20 updates of it to every robot catching up there.

So each update is replayed with only the cells that no own update of a greater version touches, and an update
left with none is not replayed, unless it is the oldest (it may hold the obstacle's smallest stamp, which gives
receivers its metadata), the newest (the longest lease) or its rectangle reaches beyond those of the newer ones
replayed (receivers keep the union of the rectangles). Replays restore state and are not judged by evidence
(evidence.py), so leaving out a cell changes no verdict. Two own updates with the same version (an exact tie, where
a clear wins whatever the order) leave the history as it is.
"""
import dataclasses


def _within(inner, outer):
    return outer[0] <= inner[0] and outer[1] <= inner[1] and inner[2] <= outer[2] and inner[3] <= outer[3]


def _union(a, b):
    return (min(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]), max(a[3], b[3]))


def deciding_updates(updates):
    """``updates``: own updates of one obstacle (codec.ObstacleUpdate, one uuid), in any order. Returns what a
    replay carries of them (see above), oldest first."""
    ordered = sorted(updates, key=lambda u: u.version)
    if len(ordered) <= 2 or len({u.version for u in ordered}) < len(ordered):
        return ordered
    newest = ordered[-1]
    touched = set(newest.marked) | set(newest.cleared)
    reach = newest.rectangle
    kept = [newest]
    for update in reversed(ordered[1:-1]):
        marked = tuple(c for c in update.marked if c not in touched)
        cleared = tuple(c for c in update.cleared if c not in touched)
        touched.update(update.marked)
        touched.update(update.cleared)
        if marked or cleared:
            kept.append(dataclasses.replace(update, marked=marked, cleared=cleared))
        elif not _within(update.rectangle, reach):
            kept.append(update)
        else:
            continue
        reach = _union(reach, update.rectangle)
    kept.append(ordered[0])
    return kept[::-1]
