"""The package's exception tree: SharingError -> InvalidMessageError, InvalidParameterError,
InvalidRequestError. All are ValueErrors, so callers that only know ValueError still catch them."""
from sharing_msgs.authority import AuthorityError


class SharingError(ValueError):
    """Base of every error this package raises on purpose."""


class InvalidMessageError(SharingError):
    """A message (proposal, update, fleet message) that must be dropped.

    ``reason`` is a short machine name (one of logic.DROP_REASONS) used as the counter key;
    ``detail`` says what was wrong, with the bad value.
    """

    def __init__(self, reason, detail):
        super().__init__("%s: %s" % (reason, detail))
        self.reason = reason
        self.detail = detail


#: What a refused message raises: one of this package's checks, or one of the rules of authority
#: (sharing_msgs.authority, shared with the bridges). Both carry ``reason`` and ``detail``.
REFUSED = (InvalidMessageError, AuthorityError)


class InvalidParameterError(SharingError):
    """A bad node parameter; the message names the parameter and its value."""


class InvalidRequestError(SharingError):
    """A refused service request (manual add); the message says why."""
