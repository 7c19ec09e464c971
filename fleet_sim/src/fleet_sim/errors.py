"""The simulator's exception tree: SimError → WorldError → WorldSyntaxError,
SimError → InvalidRequestError, SimError → MapError."""


class SimError(Exception):
    """Base of every error the simulator raises on purpose."""


class WorldError(SimError):
    """A world file that cannot be used as written; names the file and line."""

    def __init__(self, path, line, reason):
        self.path = path
        self.line = line
        self.reason = reason
        where = "%s:%d" % (path, line) if line else str(path)
        super().__init__("%s: %s" % (where, reason))


class WorldSyntaxError(WorldError):
    """A world file that cannot be parsed at all (bad token, unbalanced brackets...)."""


class InvalidRequestError(SimError):
    """A run-time request (service call, command) with a bad value; the simulation goes on."""


class MapError(SimError):
    """A map image or map YAML that map_server could not load either."""
