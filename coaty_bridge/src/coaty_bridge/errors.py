"""Exception tree of coaty_bridge. Every error carries a short ``reason`` used as
the name of its drop counter on /diagnostics."""


class CoatyError(Exception):
    """Base of everything coaty_bridge raises on bad input."""
    reason = "invalid"


class InvalidTopicError(CoatyError, ValueError):
    """The MQTT topic is not a Coaty topic we can use."""
    reason = "invalid_topic"


class ProtocolVersionError(InvalidTopicError):
    """A Coaty topic of another protocol version than 3."""
    reason = "wrong_protocol_version"


class InvalidNameError(InvalidTopicError):
    """A Coaty name (namespace, objectType, channel id, robot) with NUL, '/', '+' or '#'."""
    reason = "invalid_name"


class InvalidSourceIdError(InvalidTopicError):
    """A sourceId or correlationId that is not a UUID."""
    reason = "invalid_source_id"


class InvalidPayloadError(CoatyError, ValueError):
    """The payload is not a valid event of the kind its topic announces."""
    reason = "invalid_payload"


class PayloadTooLargeError(InvalidPayloadError):
    """The payload is longer than the configured limit."""
    reason = "oversized"


class InvalidJsonError(InvalidPayloadError):
    """The payload is not UTF-8 JSON."""
    reason = "invalid_json"


class NonFiniteNumberError(InvalidPayloadError):
    """The payload contains NaN or Infinity (not JSON, and Coaty JS rejects it)."""
    reason = "non_finite_number"


class MissingFieldError(InvalidPayloadError):
    """A required field is absent."""
    reason = "missing_field"


class WrongTypeError(InvalidPayloadError):
    """A field has the wrong JSON type."""
    reason = "wrong_type"


class OutOfRangeError(InvalidPayloadError):
    """A field has the right type but an impossible value (index outside the grid, ...)."""
    reason = "out_of_range"


class TooManyIndexesError(InvalidPayloadError):
    """An index array is longer than the grid or the configured maximum."""
    reason = "too_many_indexes"


class ForgedSourceError(InvalidPayloadError):
    """An obstacle whose ``source`` is not the robot that sent it (authenticate_sources)."""
    reason = "forged_source"


class FootprintTooLargeError(OutOfRangeError):
    """A footprint advert wider than ``max_footprint_extent``: not a robot (issue 27, item 10)."""
    reason = "footprint_too_large"


class UnknownRobotError(InvalidPayloadError):
    """A footprint advert of a robot that is not in ``known_robots`` (issue 27, item 10)."""
    reason = "unknown_robot"


class ObstacleExtentError(OutOfRangeError):
    """An obstacle's rectangle is longer than max_obstacle_extent (the handler's cap)."""
    reason = "oversized_rectangle"


class RectangleCellsError(TooManyIndexesError):
    """An obstacle declares more cells than its rectangle holds (issue 43, item 1); found before the
    index sets are expanded."""
    reason = "more_cells_than_rectangle"


class CellsOutsideRectangleError(OutOfRangeError):
    """A cell of an obstacle lies outside its rectangle (issue 43, item 1)."""
    reason = "cells_outside_rectangle"


class ImplausibleEvidenceError(InvalidPayloadError):
    """No cell of an obstacle message lies within its sender's advertised sensor reach of a pose it
    advertised near the message's stamp (issue 43, plausible evidence)."""
    reason = "implausible_evidence"


class ReservedSourceError(InvalidPayloadError):
    """An obstacle under a name no robot may use (master control's: its areas come from the VDA 5050
    bridge of each robot, never over Coaty)."""
    reason = "reserved_source"


class ObstacleCellsError(TooManyIndexesError):
    """An obstacle declares more cells than max_obstacle_cells (the handler's cap); found
    before the index sets are expanded."""
    reason = "too_many_obstacle_cells"
