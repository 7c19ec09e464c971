"""fleet_tests.scenario.GoalClient: a status that arrives while a goal is being sent is handled,
not dropped with actionlib's "[ERROR] Got a transition callback on a goal handle that we're not
tracking" (ros/actionlib#206, which make demo printed 1-5 times per run). No ROS master: the
action client underneath is a stand-in whose send_goal lets the "status thread" deliver the
goal's first transition before send_goal returns, as a fast server and a busy process do."""
import threading

import actionlib
import actionlib.simple_action_client as sac
import pytest
import rospy
from actionlib.action_client import ClientGoalHandle, CommState, CommStateMachine
from move_base_msgs.msg import MoveBaseActionGoal, MoveBaseGoal

from fleet_tests.scenario import GoalClient


class FastServer:
    """ActionClient stand-in: the goal's ACTIVE transition comes from another thread at once."""

    def __init__(self, ns, _spec):
        self.ns = ns
        self.count = 0
        self.threads = []
        self.machines = []

    def send_goal(self, goal, transition_cb=None, feedback_cb=None):
        self.count += 1
        action_goal = MoveBaseActionGoal(goal=goal)
        action_goal.goal_id.id = "goal-%d" % self.count
        csm = CommStateMachine(action_goal, transition_cb, feedback_cb, None, None)
        self.machines.append(csm)
        self.transition(csm, CommState.ACTIVE, wait=0.3)
        return ClientGoalHandle(csm)

    def transition(self, csm, state, wait=None):
        """csm goes to state in the "status thread"; waits up to `wait` s for its callback to return."""
        def status_thread():
            with csm.mutex:
                csm.transition_to(state)
        t = threading.Thread(target=status_thread)
        t.start()
        self.threads.append(t)
        t.join(wait)

    def join(self):
        for t in self.threads:
            t.join(5.0)
            assert not t.is_alive(), "a transition callback never returned (deadlock)"


@pytest.fixture
def errors(monkeypatch):
    logged = []
    monkeypatch.setattr(rospy, "logerr", lambda text, *args: logged.append(text % args if args else text))
    monkeypatch.setattr(sac, "ActionClient", FastServer)
    return logged


def test_transition_during_send_goal_is_tracked(errors):
    client = GoalClient("/robot_0/move_base", None)
    client.send_goal(MoveBaseGoal())
    client.action_client.join()
    assert errors == []
    assert client.simple_state == actionlib.SimpleGoalState.ACTIVE


def test_stock_client_drops_it(errors):
    """The check above is red with actionlib's own client: the race is real, not a test artefact."""
    client = actionlib.SimpleActionClient("/robot_0/move_base", None)
    client.send_goal(MoveBaseGoal())
    client.action_client.join()
    assert any("not tracking" in e for e in errors), errors
    assert client.simple_state == actionlib.SimpleGoalState.PENDING


def test_replaced_goal_is_ignored_but_a_stranger_is_an_error(errors):
    client = GoalClient("/robot_0/move_base", None)
    client.send_goal(MoveBaseGoal())
    first = client.action_client.machines[0]
    client.send_goal(MoveBaseGoal())          # replaces the running first goal
    server = client.action_client
    server.transition(first, CommState.DONE)  # the first goal's preemption arrives later
    server.join()
    assert errors == []
    assert client.simple_state == actionlib.SimpleGoalState.ACTIVE
    stranger = MoveBaseActionGoal()
    stranger.goal_id.id = "someone-else"
    server.transition(CommStateMachine(stranger, client._handle_transition, None, None, None), CommState.ACTIVE)
    server.join()
    assert any("not tracking" in e for e in errors), errors
