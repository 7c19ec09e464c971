"""Exception tree of the replay: ReplayError -> BagOpenError, InputError, TransformError."""


class ReplayError(Exception):
    """Base of everything the replay raises on purpose."""


class InputError(ReplayError):
    """A bad command line, parameter file or map: the replay cannot start."""


class BagOpenError(ReplayError):
    """The bag cannot be opened or read at all (missing, not a bag, unrecoverable)."""


class TransformError(ReplayError):
    """A transform lookup failed; ``reason`` is the counter it goes to."""

    def __init__(self, reason, message):
        super().__init__(message)
        self.reason = reason


class MissingTopicError(InputError):
    """The bag has no LaserScan topic to replay (or not for a requested robot)."""
