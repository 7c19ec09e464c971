"""Convergence: the same updates, in any order and with duplicates, give every handler the same
obstacles and cells (DESIGN.md §6). Property tests over random interleavings (hypothesis)."""
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from handler_fixtures import U, Recorder, proposal, rect, state, update

EXAMPLES = settings(max_examples=500, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

CELLS = st.lists(st.integers(0, 15), max_size=6)
# (marked, cleared) of one message: never both empty (a message without cells carries nothing and
# is refused on the fleet channel, see test_handler_bad_input).
CHANGES = st.tuples(CELLS, CELLS).filter(lambda mc: mc[0] or mc[1])
RECTANGLES = [rect(0, 0, 1, 1), rect(0.5, 0.5, 1.5, 1.5), rect(3, 3, 4, 4)]


@st.composite
def fleet_messages(draw):
    """Messages about up to three uuids from up to four robots, with clashing stamps and
    different metadata, as a fleet could produce them."""
    msgs = []
    for _ in range(draw(st.integers(1, 12))):
        marked, cleared = draw(CHANGES)
        msgs.append(update(uuid=draw(st.sampled_from([U("u1"), U("u2"), U("u3")])), marked=marked,
                           cleared=cleared, version=draw(st.integers(1, 4)),
                           source=draw(st.sampled_from(["robot_1", "robot_2", "robot_3", "robot_4"])),
                           deadline=draw(st.sampled_from([30, 60])),
                           rectangle=draw(st.sampled_from(RECTANGLES))))
    return msgs


@EXAMPLES
@given(msgs=fleet_messages(), data=st.data())
def test_observers_converge_whatever_the_order_and_duplicates(msgs, data):
    observers = [Recorder("observer_%d" % i) for i in range(3)]
    for r in observers:
        order = data.draw(st.permutations(msgs))
        dups = data.draw(st.lists(st.sampled_from(msgs), max_size=4))
        for dup in dups:  # duplicates at random places
            order.insert(data.draw(st.integers(0, len(order))), dup)
        for m in order:
            assert r.handler.on_external(m)
    reference = state(observers[0].handler)
    for r in observers[1:]:
        assert state(r.handler) == reference
    assert [u for u, *_ in reference] == sorted({m.uuid for m in msgs})


@EXAMPLES
@given(data=st.data())
def test_robots_proposing_updating_and_exchanging_in_any_interleaving_converge(data):
    """Robots propose (sometimes the same obstacle at once), update what they hold, and their
    messages reach every other robot in any order, some twice. At the end every robot holds
    the same obstacles and cells, and no authorised obstacle is lost."""
    n = data.draw(st.integers(2, 3), label="robots")
    robots = [Recorder("robot_%d" % i, uuids="r%d" % i) for i in range(n)]
    sent_count = [0] * n
    pending, delivered, authorised = [], [], set()

    def ship(i):
        for m in robots[i].fleet[sent_count[i]:]:
            pending.extend((m, j) for j in range(n) if j != i)
        sent_count[i] = len(robots[i].fleet)

    for _ in range(data.draw(st.integers(1, 14), label="steps")):
        kind = data.draw(st.sampled_from(["propose", "update", "deliver", "deliver", "duplicate"]))
        i = data.draw(st.integers(0, n - 1))
        h = robots[i].handler
        if kind == "propose":
            shared = h.on_proposal(proposal(cells=data.draw(CELLS.filter(bool)), source="robot_%d" % i,
                                            rectangle=data.draw(st.sampled_from(RECTANGLES))))
            if shared is not None:
                authorised.add(shared.uuid)
        elif kind == "update" and len(h):
            held = data.draw(st.sampled_from(h.obstacles()))
            # the layer usually sends max+1; a stale version exercises the re-stamp guard
            version = held.version + data.draw(st.sampled_from([1, 1, 0, -1]))
            marked, cleared = data.draw(CHANGES)
            h.on_internal_update(update(held.uuid, marked=marked, cleared=cleared,
                                        version=max(version, 0), source="robot_%d" % i,
                                        deadline=held.deadline, rectangle=held.rectangle))
        elif kind == "deliver" and pending:
            m, j = pending.pop(data.draw(st.integers(0, len(pending) - 1)))
            robots[j].handler.on_external(m)
            delivered.append((m, j))
        elif kind == "duplicate" and delivered:
            m, j = data.draw(st.sampled_from(delivered))
            robots[j].handler.on_external(m)
        ship(i)

    for m, j in data.draw(st.permutations(pending), label="final delivery"):
        robots[j].handler.on_external(m)
    for m, j in data.draw(st.lists(st.sampled_from(delivered), max_size=3) if delivered
                          else st.just([]), label="late duplicates"):
        robots[j].handler.on_external(m)

    reference = state(robots[0].handler)
    for r in robots[1:]:
        assert state(r.handler) == reference
    assert {u for u, *_ in reference} == authorised
    for r in robots:
        assert sum(v for k, v in r.handler.counters.items() if k.startswith("dropped_")) == 0


@EXAMPLES
@given(first=st.permutations([0, 1, 2]), order=st.data())
def test_simultaneous_proposals_of_one_obstacle_are_both_kept_on_every_robot(first, order):
    """Two robots propose the same obstacle before hearing of each other: each authorises its
    own uuid, and every robot, whatever the delivery order, ends holding both."""
    robots = [Recorder("robot_%d" % i, uuids="r%d" % i) for i in range(3)]
    a = robots[0].handler.on_proposal(proposal(cells=(1, 2, 3), source="robot_0"))
    b = robots[1].handler.on_proposal(proposal(cells=(2, 3, 4), source="robot_1"))
    msgs = [(a, 1), (a, 2), (b, 0), (b, 2)]
    for m, j in order.draw(st.permutations(msgs)):
        robots[j].handler.on_external(m)
    expected = sorted([(a.uuid, "robot_0", (1, 2, 3)), (b.uuid, "robot_1", (2, 3, 4))])
    for r in robots:
        assert [(h.uuid, h.source, h.cells) for h in r.handler.obstacles()] == expected
    # and each expires on its own deadline, counted from its local arrival
    for r in robots:
        r.clock.now += 60
        assert r.handler.expire() == sorted([a.uuid, b.uuid])
        assert len(r.handler) == 0


def test_after_hearing_of_an_obstacle_a_robot_no_longer_proposes_it():
    """The other order of the race: the share arrives first, so the second proposal is redundant
    and the fleet ends with one obstacle."""
    r0, r1 = Recorder("robot_0", uuids="r0"), Recorder("robot_1", uuids="r1")
    a = r0.handler.on_proposal(proposal(cells=(1, 2), source="robot_0"))
    r1.handler.on_external(a)
    assert r1.handler.on_proposal(proposal(cells=(2, 3), source="robot_1")) is None
    assert state(r0.handler) == state(r1.handler)
