"""Exception tree of fleet_nav."""


class NavError(Exception):
    """Base of every fleet_nav error."""


class ParameterError(NavError, ValueError):
    """A parameter has a bad value; the message names the parameter and the value."""


class GoalRejected(NavError, ValueError):
    """A goal that cannot be accepted (outside the map, inside an obstacle, not finite)."""
