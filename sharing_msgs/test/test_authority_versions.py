"""The version step of the rules of authority and the fleet console's operator margin: one rule for every
source (operators are not exempt), and no receiver may set a step an operator's action cannot pass."""
import pytest

from sharing_msgs.authority import MIN_VERSION_STEP, OPERATOR_VERSION_MARGIN, AuthorityError, PeerPolicy


def test_the_least_step_leaves_room_for_an_operator_and_a_robot_a_margin_behind():
    assert MIN_VERSION_STEP >= 2 * OPERATOR_VERSION_MARGIN
    policy = PeerPolicy(max_extent=10.0, max_lifetime=60, max_version_step=MIN_VERSION_STEP)
    robot_holds, page_heard = 7, 7 + OPERATOR_VERSION_MARGIN
    policy.check_version(page_heard + OPERATOR_VERSION_MARGIN, robot_holds)   # taken
    with pytest.raises(AuthorityError) as err:
        policy.check_version(page_heard + OPERATOR_VERSION_MARGIN + 1, robot_holds)
    assert err.value.reason == "implausible_version"


@pytest.mark.parametrize("step", [0, 1, OPERATOR_VERSION_MARGIN, MIN_VERSION_STEP - 1])
def test_a_step_an_operators_action_could_fail_is_refused_naming_it(step):
    with pytest.raises(ValueError, match="max_version_step %d must be an integer >= %d" % (step, MIN_VERSION_STEP)):
        PeerPolicy(max_extent=10.0, max_lifetime=60, max_version_step=step)


def test_no_source_is_exempt_from_the_step():
    """An operator's login is trusted to act, not to use up the version space: the cap is the same for it."""
    policy = PeerPolicy(max_extent=10.0, max_lifetime=60, max_version_step=MIN_VERSION_STEP)
    with pytest.raises(AuthorityError):
        policy.check_version(2 ** 53 - 1, 5)
