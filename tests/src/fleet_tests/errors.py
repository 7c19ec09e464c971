"""The error of a fleet scenario step, shared by the scenario helpers and the broker byte counters."""


class ScenarioError(Exception):
    """A scenario step could not be carried out (bad goal name, service refused, ...)."""
