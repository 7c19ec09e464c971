"""replay.py: a replay of this robot's own updates leaves out what its newer updates decided, and a receiver (the
real SharingHandler) ends in the same state as with the whole history, whatever else it heard and in what order."""
import uuid as uuidlib

from hypothesis import given, settings, strategies as st

from coaty_bridge import replay
from coaty_bridge.client import BridgeConfig, CoatyBridgeClient
from coaty_bridge.codec import ObstacleUpdate
from sharing_handler_py.logic import SharingHandler
from sharing_handler_py.validation import Geometry, Obstacle, Rectangle

GRID = Geometry(0.05, 0.0, 0.0, 100, 100)
POOL = [y * 100 + x for y in range(6) for x in range(6)]    # 36 cells in (0, 0)-(0.3, 0.3)
RECT = (0.0, 0.0, 0.3, 0.3)
UUID = str(uuidlib.UUID(int=7))


def update(version, marked, cleared, source="robot_0", rectangle=RECT, deadline=600):
    return ObstacleUpdate(uuid=UUID, source=source, version=version, stamp=1000.0 + version, frame_id="map",
                          deadline=deadline, rectangle=rectangle, resolution=GRID.resolution, origin_x=0.0,
                          origin_y=0.0, size_x=GRID.size_x, size_y=GRID.size_y, marked=tuple(marked),
                          cleared=tuple(cleared))


def to_obstacle(u):
    return Obstacle(uuid=u.uuid, marked=u.marked, cleared=u.cleared, deadline=u.deadline,
                    rectangle=Rectangle(*u.rectangle), source=u.source, geometry=GRID, version=u.version,
                    frame_id=u.frame_id, stamp=u.stamp)


def receive(messages):
    """A receiver's handler after ``messages``: (kind, update), kind 'state' (a replay, as a Resolve) or 'live'."""
    handler = SharingHandler("robot_5", lambda: 5000.0, 1200, on_to_layer=lambda o: None,
                             on_to_fleet=lambda o: None, on_expired=lambda u: None, geometry=GRID)
    for kind, u in messages:
        (handler.on_state if kind == "state" else handler.on_external)(to_obstacle(u))
    held = handler.get(UUID)
    return None if held is None else (held.cells, held.version, held.rectangle, held.source, held.remaining)


def history(draw_sets):
    """Own updates v1..vn from a list of (marked, cleared) cell sets."""
    return [update(v, m, c) for v, (m, c) in enumerate(draw_sets, start=1)]


cell_sets = st.tuples(st.sets(st.sampled_from(POOL), max_size=8), st.sets(st.sampled_from(POOL), max_size=6)).filter(
    lambda mc: mc[0] or mc[1])


@settings(max_examples=300, deadline=None)
@given(own=st.lists(cell_sets, min_size=1, max_size=25), others=st.lists(
    st.tuples(st.integers(1, 30), cell_sets), max_size=6), order=st.randoms(use_true_random=False))
def test_a_receiver_ends_the_same_with_the_replay_as_with_the_whole_history(own, others, order):
    mine = history(own)
    mine[0] = update(1, own[0][0] or POOL[:1], own[0][1])   # a first share marks something
    theirs = [("live", update(v, m, c, source="robot_9")) for v, (m, c) in others]
    full = [("state", u) for u in mine]
    slots = sorted(order.sample(range(len(full) + len(theirs)), len(theirs)))   # where the others come in
    kept = {u.version: u for u in replay.deciding_updates(mine)}

    def interleave(own_messages):
        out, own_iter, their_iter = [], iter(own_messages), iter(theirs)
        for i in range(len(full) + len(theirs)):
            if slots and i in slots:
                out.append(next(their_iter))
            else:
                out.append(next(own_iter))
        return [m for m in out if m is not None]
    whole = receive(interleave(full))
    # the replay in its own order (oldest first, as a Resolve carries it), the left-out ones missing
    replayed = receive(interleave([("state", kept[u.version]) if u.version in kept else None for _, u in full]))
    assert replayed == whole


def test_a_long_watched_obstacle_replays_a_few_updates_instead_of_its_history():
    # 24 updates, each marking 5 and clearing 3 of 40 cells in turn (the scale bench's monitoring updates)
    cells = POOL[:40] if len(POOL) >= 40 else POOL + [600 + i for i in range(40 - len(POOL))]
    mine = [update(1, cells[:10], ())]
    for v in range(2, 25):
        k = (v * 8) % 40
        mine.append(update(v, [cells[(k + i) % 40] for i in range(5)], [cells[(k + 5 + i) % 40] for i in range(3)],
                           rectangle=(0.0, 0.0, 0.4, 0.4)))
    kept = replay.deciding_updates(mine)
    assert [u.version for u in kept][:1] == [1] and kept[-1] == mine[-1]
    assert len(kept) <= 7, [u.version for u in kept]   # 40 cells, 8 per update: the last 5 decide them all
    assert all(u.marked or u.cleared for u in kept)


def test_the_oldest_and_the_newest_go_whole_and_a_wider_rectangle_is_kept():
    first = update(1, [0], ())
    wider = update(2, [1], (), rectangle=(0.0, 0.0, 0.6, 0.6))
    narrow = update(3, [1], ())
    last = update(4, [0, 1], ())
    assert replay.deciding_updates([last, narrow, wider, first]) == [first, wider, last]
    # the same history with v2 inside the newer rectangles: nothing of it is left to replay
    inside = update(2, [1], ())
    assert replay.deciding_updates([first, inside, narrow, last]) == [first, last]


def test_a_cell_decided_by_a_newer_update_is_left_out_of_the_older_one():
    first, middle, last = update(1, [0, 1], ()), update(2, [2, 3], [0]), update(3, [3], ())
    assert replay.deciding_updates([first, middle, last]) == [first, update(2, [2], [0]), last]


def test_two_updates_of_one_version_leave_the_history_as_it_is():
    # an exact tie: a clear wins whatever the order, so neither says nothing
    history_ = [update(1, [0], ()), update(2, [1], ()), update(2, (), [1]), update(3, [1], ())]
    assert replay.deciding_updates(history_) == sorted(history_, key=lambda u: u.version)


def test_a_bridge_counts_what_its_replays_leave_out(make_update):
    client = CoatyBridgeClient(BridgeConfig("robot_0", obstacle_area_size=0), lambda u, t: None,
                               clock=lambda: 1000.0)   # never started: the updates wait in its offline queue
    uuid = str(uuidlib.uuid4())
    for version in range(1, 5):
        client.publish_obstacle(make_update(uuid=uuid, version=version, marked=(880221,), cleared=()))
    replayed = client._replayable_own_updates()
    assert [u.version for u in replayed] == [1, 4]
    assert client.counters()["replay_updates_left_out"] == 2
