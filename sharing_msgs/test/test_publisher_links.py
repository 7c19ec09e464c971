"""PublisherLinkWatch: a subscription that rospy left without a link to a publisher (its
registration race drops the master's update) is linked again; the decision (LinkBook) is pinned
without a master, the repair through real rospy and a real rosmaster."""
import json
import os
import subprocess
import sys

import pytest

from sharing_msgs.publisher_links import LinkBook, PublisherLinkWatch

HERE = os.path.dirname(os.path.abspath(__file__))
CMD_VEL = "/robot_4/cmd_vel"
NAV = ("/robot_4/move_base", "http://127.0.0.1:40217/")


def _links(*pairs):
    linked = set(pairs)
    return lambda topic, uri: (topic, uri) in linked


def test_a_linked_publisher_is_never_announced():
    book = LinkBook()
    published = {CMD_VEL: dict([NAV])}
    for _ in range(3):
        assert book.check(published, _links((CMD_VEL, NAV[1]))) == ({}, [])


def test_unlinked_at_two_checks_in_a_row_is_announced_once_per_check():
    book = LinkBook()
    published = {CMD_VEL: dict([NAV])}
    # First look: maybe still connecting, leave it.
    assert book.check(published, _links()) == ({}, [])
    assert book.check(published, _links()) == ({CMD_VEL: [NAV[0]]}, [])
    assert book.check(published, _links()) == ({CMD_VEL: [NAV[0]]}, [])
    assert book.check(published, _links((CMD_VEL, NAV[1]))) == ({}, [])
    assert book.mended == 1


def test_a_publisher_linked_in_between_starts_afresh():
    book = LinkBook()
    published = {CMD_VEL: dict([NAV])}
    book.check(published, _links())
    book.check(published, _links((CMD_VEL, NAV[1])))
    assert book.check(published, _links()) == ({}, [])  # one look again before announcing


def test_gives_up_after_max_announcements_and_reports_it_once():
    book = LinkBook(max_announcements=2)
    published = {CMD_VEL: dict([NAV])}
    results = [book.check(published, _links()) for _ in range(6)]
    assert results[1] == ({CMD_VEL: [NAV[0]]}, [])
    assert results[2] == ({CMD_VEL: [NAV[0]]}, [(CMD_VEL, NAV[0])])
    assert results[3:] == [({}, [])] * 3


def test_a_restarted_publisher_under_a_new_uri_is_watched_afresh():
    book = LinkBook(max_announcements=1)
    book.check({CMD_VEL: dict([NAV])}, _links())
    book.check({CMD_VEL: dict([NAV])}, _links())          # announced and given up
    restarted = {CMD_VEL: {NAV[0]: "http://127.0.0.1:40999/"}}
    assert book.check(restarted, _links()) == ({}, [])
    assert book.check(restarted, _links()) == ({CMD_VEL: [NAV[0]]}, [(CMD_VEL, NAV[0])])


def test_only_the_unlinked_publisher_of_a_topic_is_named():
    book = LinkBook()
    published = {"/tf": {"/robot_0/move_base": "http://a/", "/fleet_sim": "http://b/"}}
    linked = _links(("/tf", "http://b/"))
    book.check(published, linked)
    assert book.check(published, linked) == ({"/tf": ["/robot_0/move_base"]}, [])


@pytest.mark.parametrize("period", [0, -1, float("nan")])
def test_a_bad_period_is_refused_with_the_node_named(period):
    with pytest.raises(ValueError, match="robot_4/sharing_handler.*period"):
        PublisherLinkWatch("robot_4/sharing_handler", period=period)


def _run_probe(env, *args):
    sub = subprocess.Popen([sys.executable, os.path.join(HERE, "publisher_links_probe.py"), "sub"] + list(args),
                           env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    pub = None
    try:
        assert sub.stdout.readline().strip() == "ready", sub.stderr.read()[-1500:]
        pub = subprocess.Popen([sys.executable, os.path.join(HERE, "publisher_links_probe.py"), "pub"],
                               env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        out, err = sub.communicate(timeout=120)
    finally:
        if pub is not None:
            pub.terminate()
            pub.wait(10)
        if sub.poll() is None:
            sub.kill()
    lines = [line for line in out.splitlines() if line.startswith("{")]
    assert lines, (sub.returncode, out[-500:], err[-1500:])
    return json.loads(lines[-1])


def test_without_the_watch_the_lost_update_leaves_the_subscription_deaf(ros_env):
    """The failure the watch exists for: the probe's dropped update is never made up for."""
    result = _run_probe(ros_env, "--no-watch", "--wait", "6")
    assert result["dropped"] == 1 and result["received"] == 0, result


def test_the_watch_links_the_subscription_after_the_lost_update(ros_env):
    result = _run_probe(ros_env)
    assert result["dropped"] == 1 and result["received"] > 0 and result["mended"] == 1, result
