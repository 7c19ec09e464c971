"""The one error of the rules of authority: a message that this receiver's policy refuses."""


class AuthorityError(ValueError):
    """A message beyond what this receiver lets a peer do. ``reason`` is a short machine name (the
    drop counter, e.g. ``oversized_rectangle``), ``detail`` says what was wrong, with the value.
    Each package counts it under its own prefix (the handler ``dropped_<reason>``, the bridge
    ``dropped.<reason>``)."""

    def __init__(self, reason, detail):
        super().__init__("%s: %s" % (reason, detail))
        self.reason = reason
        self.detail = detail
