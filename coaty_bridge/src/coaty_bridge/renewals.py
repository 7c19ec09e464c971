"""Lease renewals of far copies, several obstacles in one Coaty Channel event (issue 29, traffic).

An obstacle's monitoring updates go only to the robots around it (``obstacle_area_size``), so the
far robots' copies would run out first; its last updater sends them a renewal shortly before. Sent
one obstacle object each (~480 bytes), renewals were about a fifth of what every robot received in
a busy fleet, and most of each was the same source, frame and grid repeated. So the renewals a
bridge has due go out together, on ``coaty/3/<ns>/CHN:org.fleetsharing.ObstacleRenewals/<sourceId>``,
which every bridge observes, as one CoatyObject::

    {"objectType": "org.fleetsharing.ObstacleRenewals", "coreType": "CoatyObject",
     "objectId": <uuid4 per event>, "name": "robot_0",
     "source": "robot_0", "frameId": "map", "resolution": 0.05, "origin": [x, y],
     "size": [size_x, size_y],
     "obstacles": [[uuid, version, stamp, deadline, [min_x, min_y, max_x, max_y],
                    markedIndexes, clearedIndexes, evidence], ...]}

Each entry means exactly the obstacle object with those fields plus the shared ones (its
``deadline`` aged to the moment of sending, as every deadline on the wire; ``evidence``, where its
sender saw the cells, is left out when unknown), and is validated by
``codec.obstacle_from_object``, the one check of an obstacle: a bad entry is reported alone and
the good ones are kept.
"""
from coaty_bridge import codec, compact
from coaty_bridge.errors import OutOfRangeError, WrongTypeError

CHANNEL = "org.fleetsharing.ObstacleRenewals"
OBJECT_TYPE = "org.fleetsharing.ObstacleRenewals"
#: entries in one event at most, sent and received (a bridge renews its own updates: a handful)
MAX_ENTRIES = 64
_SHARED = ("source", "frameId", "resolution", "origin", "size")


def _shared_fields(update):
    return (update.source, update.frame_id, update.resolution, (update.origin_x, update.origin_y),
            (update.size_x, update.size_y))


def renewals_objects(updates, object_id_factory):
    """ObstacleUpdates -> the renewals objects carrying them: one per source, frame and grid, each with
    at most MAX_ENTRIES entries."""
    groups = {}
    for update in updates:
        groups.setdefault(_shared_fields(update), []).append(update)
    objects = []
    for (source, frame_id, resolution, origin, size), members in groups.items():
        for start in range(0, len(members), MAX_ENTRIES):
            chunk = members[start:start + MAX_ENTRIES]
            objects.append((tuple(chunk), {
                "objectType": OBJECT_TYPE, "coreType": "CoatyObject", "objectId": object_id_factory(),
                "name": source, "source": source, "frameId": frame_id, "resolution": resolution,
                "origin": list(origin), "size": list(size),
                "obstacles": [_entry(u) for u in chunk]}))
    return objects


def _entry(update):
    entry = [update.uuid, update.version, update.stamp, update.deadline, list(update.rectangle),
             compact.encode_indexes(update.marked), compact.encode_indexes(update.cleared)]
    if update.evidence is not None:
        entry.append(codec.evidence_to_list(update.evidence))
    return entry


def renewals_payload(obj):
    """The Channel payload of one renewals object (UTF-8 JSON, no NaN)."""
    return codec.dump({"object": obj})


def decode_renewals(data, object_type, limits=codec.CodecLimits()):
    """Channel payload dict -> codec.ObstacleBatch of obstacles of ``object_type`` (the fleet's plain
    obstacle objectType). Raises a CoatyError when the event itself is bad; a bad entry is reported
    in ``errors`` without losing the others."""
    obj = codec._get(data, "object")
    if not isinstance(obj, dict):
        raise WrongTypeError("renewals object %s is not a JSON object" % codec._short(obj))
    if codec._str(obj, "objectType") != OBJECT_TYPE:
        raise WrongTypeError("objectType %r is not %r" % (codec._short(obj["objectType"]), OBJECT_TYPE))
    if codec._str(obj, "coreType") != "CoatyObject":
        raise WrongTypeError("coreType %r is not 'CoatyObject'" % codec._short(obj["coreType"]))
    shared = {key: codec._get(obj, key) for key in _SHARED}
    entries = codec._get(obj, "obstacles")
    if not isinstance(entries, list):
        raise WrongTypeError("obstacles %s is not a list" % codec._short(entries))
    if len(entries) > MAX_ENTRIES:
        raise OutOfRangeError("obstacles: %d renewals in one event, more than %d" % (len(entries), MAX_ENTRIES))
    found, errors = [], []
    for k, entry in enumerate(entries):
        if not isinstance(entry, list) or len(entry) not in (7, 8):
            errors.append(WrongTypeError("renewal %d %s is not [uuid, version, stamp, deadline, rectangle, "
                                         "markedIndexes, clearedIndexes(, evidence)]" % (k, codec._short(entry))))
            continue
        uuid, version, stamp, deadline, rectangle, marked, cleared = entry[:7]
        full = dict(shared, objectType=object_type, coreType="CoatyObject", objectId=uuid, name="", uuid=uuid,
                    version=version, stamp=stamp, deadline=deadline, rectangle=rectangle,
                    markedIndexes=marked, clearedIndexes=cleared, evidence=entry[7] if len(entry) == 8 else None)
        codec.collect_obstacle(full, object_type, limits, found, errors)
    return codec.ObstacleBatch(tuple(found), tuple(errors))
