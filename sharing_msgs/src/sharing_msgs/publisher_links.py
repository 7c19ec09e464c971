"""Links a subscription to every publisher of its topic, mending what rospy can lose at start-up.

Why: rospy (1.16, Noetic's and Debian's) puts the publisher list that registerSubscriber returns
and every list the master pushes (publisherUpdate) on one queue, and its RegManager acts only on
the newest entry per topic. When a publisher registers while a subscriber is registering, the
master's publisherUpdate (listing it) can be queued before the registration's own reply (not
listing it yet): the stale reply wins, the update is dropped, and the subscription never links to
that publisher. Nothing logs it. Seen in the dead-end bench: the simulator's subscription to
robot_4/cmd_vel missed robot_4's navigation host, so robot_4 never moved.

``PublisherLinkWatch`` compares, every few seconds, each of the node's subscriptions with the
master's publishers of its topic. A publisher found unlinked at two checks in a row is announced
to the node again (the master's own publisherUpdate call, sent to the node's XML-RPC server), so
rospy links to it the normal way. Publishers that are still connecting are not touched (the
second look), and one that cannot be linked after a few tries is reported once and left alone
(a node that died without unregistering stays in the master's list).

``LinkBook`` is the decision, free of ROS and tested without a master; ``start_watch`` is the
rospy side.
"""
import logging
import threading
import time

_log = logging.getLogger(__name__)

#: Wall seconds between two checks; a missed link is mended within about two of them.
DEFAULT_PERIOD = 5.0
#: Announcements of one publisher to one subscription before it is reported and left alone.
MAX_ANNOUNCEMENTS = 5


class LinkBook:
    """Which publishers to announce again: those unlinked at two checks in a row.

    ``check(published, linked)`` takes the master's view ``{topic: {publisher node: its XML-RPC
    URI}}`` for the node's subscribed topics and ``linked(topic, uri) -> bool`` for the node's own
    links. It returns ``(announce, given_up)``: ``{topic: [node, ...]}`` to announce again now and
    ``[(topic, node)]`` that reached ``max_announcements`` at this check.
    """

    def __init__(self, max_announcements=MAX_ANNOUNCEMENTS):
        self.max_announcements = int(max_announcements)
        self._unlinked_before = set()   # (topic, node, uri) unlinked at the previous check
        self._announced = {}            # (topic, node, uri) -> announcements so far
        self.mended = 0                 # announced ones that were linked at a later check

    def check(self, published, linked):
        unlinked = set()
        for topic, publishers in published.items():
            for node, uri in publishers.items():
                key = (topic, node, uri)
                if linked(topic, uri):
                    if key in self._announced:
                        del self._announced[key]
                        self.mended += 1
                    continue
                unlinked.add(key)
        announce, given_up = {}, []
        for key in sorted(unlinked & self._unlinked_before):
            count = self._announced.get(key, 0)
            if count >= self.max_announcements:
                continue
            self._announced[key] = count + 1
            if count + 1 == self.max_announcements:
                given_up.append((key[0], key[1]))
            announce.setdefault(key[0], []).append(key[1])
        # A publisher gone from the master's list is forgotten; if it comes back it starts afresh.
        current = {(t, n, u) for t, pubs in published.items() for n, u in pubs.items()}
        self._announced = {k: v for k, v in self._announced.items() if k in current}
        self._unlinked_before = unlinked
        return announce, given_up


class PublisherLinkWatch:
    """rospy side: a daemon thread running ``LinkBook`` over this node's subscriptions.

    ``label`` names the node in logs (e.g. "robot_4/sharing_handler"). Runs on wall time, so it
    works while /clock is paused and before it starts.
    """

    def __init__(self, label, period=DEFAULT_PERIOD, max_announcements=MAX_ANNOUNCEMENTS):
        if not period > 0:
            raise ValueError("%s: publisher link check period must be > 0 s, got %r" % (label, period))
        self.label = label
        self.period = float(period)
        self.book = LinkBook(max_announcements)
        self._uris = {}                 # publisher node -> XML-RPC URI (cleared when it changes)
        self._failing = None            # the last check's error text, logged once per change
        self._thread = threading.Thread(target=self._run, name="publisher_link_watch", daemon=True)

    def start(self):
        self._thread.start()
        return self

    def _run(self):
        import rospy
        while not rospy.core.is_shutdown():
            time.sleep(self.period)
            if rospy.core.is_shutdown():
                return
            try:
                self.check_once()
                if self._failing is not None:
                    _log.info("%s: publisher link check works again", self.label)
                self._failing = None
            except Exception as err:  # noqa: BLE001 - a master hiccup must not end the watch
                text = "%s: %s" % (type(err).__name__, err)
                if text != self._failing:
                    _log.warning("%s: publisher link check failed (%s); trying again in %g s",
                                 self.label, text, self.period)
                self._failing = text

    def check_once(self):
        """One check against the master; returns the ``{topic: [node]}`` announced again."""
        import rosgraph
        import rospy
        from rospy.impl.registration import get_topic_manager
        topics = get_topic_manager()
        own_name = rospy.get_name()
        subscribed = {name for name, _type in topics.get_subscriptions()}
        if not subscribed:
            return {}
        master = rosgraph.Master(own_name)
        publishers, _subscribers, _services = master.getSystemState()
        published = {}
        for topic, nodes in publishers:
            if topic not in subscribed:
                continue
            published[topic] = {}
            for node in nodes:
                if node == own_name:
                    continue
                if node not in self._uris:
                    self._uris[node] = master.lookupNode(node)
                published[topic][node] = self._uris[node]

        def linked(topic, uri):
            impl = topics.get_subscriber_impl(topic)
            return impl is None or impl.has_connection(uri)

        # An unlinked publisher may be a node restarted under the same name (a new URI): ask again.
        for topic, nodes in published.items():
            for node, uri in list(nodes.items()):
                if not linked(topic, uri):
                    self._uris[node] = nodes[node] = master.lookupNode(node)
        announce, given_up = self.book.check(published, linked)
        if announce:
            own = _server_proxy(rospy.get_node_uri())
            for topic, nodes in announce.items():
                _log.warning("%s: subscription %s has no link to publisher(s) %s though the master lists "
                             "them (rospy dropped the master's update while registering); announcing "
                             "them to the node again", self.label, topic, ", ".join(nodes))
                own.publisherUpdate("/master", topic, sorted(published[topic].values()))
        for topic, node in given_up:
            _log.error("%s: subscription %s still has no link to publisher %s (%s) after %d announcements; "
                       "leaving it (is that node alive? `rosnode ping %s`)", self.label, topic, node,
                       published[topic][node], self.book.max_announcements, node)
        return announce


def _server_proxy(uri):
    import xmlrpc.client
    return xmlrpc.client.ServerProxy(uri)


def start_watch(label, period=DEFAULT_PERIOD):
    """Starts watching this (initialised) rospy node's subscriptions; returns the watch."""
    return PublisherLinkWatch(label, period).start()
