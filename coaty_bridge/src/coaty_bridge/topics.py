"""Coaty topic names (communication protocol version 3) as validated values.

one-way: ``coaty/3/<namespace>/<event>/<sourceId>``
two-way: ``coaty/3/<namespace>/<event>/<sourceId>/<correlationId>``
"""
import re
import uuid
from dataclasses import dataclass
from typing import Optional

from coaty_bridge.errors import (InvalidNameError, InvalidSourceIdError, InvalidTopicError,
                                 ProtocolVersionError)

PROTOCOL_NAME = "coaty"
PROTOCOL_VERSION = 3
MAX_TOPIC_BYTES = 65535

_NAME_RE = re.compile(r"^[^\u0000+#/]+$")
_UUID_RE = re.compile(r"^[0-9a-fA-F]{8}-[0-9a-fA-F]{4}-[0-9a-fA-F]{4}-[0-9a-fA-F]{4}-[0-9a-fA-F]{12}$")

ONE_WAY = {"ADV", "DAD", "CHN"}
TWO_WAY = {"DSC", "RSV", "QRY", "RTV", "UPD", "CPL", "CLL", "RTN"}
# Events whose level carries a filter after ':' (coreType, '::'objectType, channel, operation).
_FILTERED = {"ADV", "CHN", "UPD", "CLL"}


def check_name(value, what="name"):
    """Returns ``value`` if it is a valid Coaty name, else raises InvalidNameError naming it."""
    if not isinstance(value, str) or not _NAME_RE.match(value):
        raise InvalidNameError("%s %r is not a Coaty name (non-empty, no NUL, '/', '+' or '#')"
                               % (what, value))
    return value


def check_uuid(value, what="uuid"):
    """Returns ``value`` lower-cased if it is a UUID string, else raises InvalidSourceIdError."""
    if not isinstance(value, str) or not _UUID_RE.match(value):
        raise InvalidSourceIdError("%s %r is not a UUID" % (what, value))
    return value.lower()


def new_uuid():
    """A fresh lower-case UUID v4 (identity ids, correlation ids)."""
    return str(uuid.uuid4())


@dataclass(frozen=True)
class Topic:
    """One Coaty topic. ``event`` is the event code (ADV, DSC, ...); ``core_type``,
    ``object_type`` or ``filter`` hold what follows the ':' of the event level."""
    namespace: str
    event: str
    source_id: str
    correlation_id: Optional[str] = None
    core_type: Optional[str] = None
    object_type: Optional[str] = None
    filter: Optional[str] = None
    version: int = PROTOCOL_VERSION

    def __post_init__(self):
        if self.version != PROTOCOL_VERSION:
            raise ProtocolVersionError("protocol version %r is not %d" % (self.version, PROTOCOL_VERSION))
        check_name(self.namespace, "namespace")
        if self.event not in ONE_WAY and self.event not in TWO_WAY:
            raise InvalidTopicError("unknown Coaty event %r" % (self.event,))
        object.__setattr__(self, "source_id", check_uuid(self.source_id, "sourceId"))
        if self.event in TWO_WAY:
            object.__setattr__(self, "correlation_id",
                               check_uuid(self.correlation_id, "correlationId"))
        elif self.correlation_id is not None:
            raise InvalidTopicError("one-way event %s with a correlationId %r"
                                    % (self.event, self.correlation_id))
        for value, what in ((self.core_type, "coreType"), (self.object_type, "objectType"),
                            (self.filter, "event filter")):
            if value is not None:
                check_name(value, what)

    def event_level(self):
        if self.object_type is not None:
            return "%s::%s" % (self.event, self.object_type)
        if self.core_type is not None:
            return "%s:%s" % (self.event, self.core_type)
        if self.filter is not None:
            return "%s:%s" % (self.event, self.filter)
        return self.event

    def __str__(self):
        levels = [PROTOCOL_NAME, str(self.version), self.namespace, self.event_level(), self.source_id]
        if self.correlation_id is not None:
            levels.append(self.correlation_id)
        return "/".join(levels)


def parse_topic(text):
    """Parses an MQTT topic into a Topic; raises an InvalidTopicError subclass."""
    if not isinstance(text, str):
        raise InvalidTopicError("topic %r is not a string" % (text,))
    if len(text.encode("utf-8", "surrogatepass")) > MAX_TOPIC_BYTES:
        raise InvalidTopicError("topic longer than %d bytes" % MAX_TOPIC_BYTES)
    levels = text.split("/")
    if len(levels) not in (5, 6) or levels[0] != PROTOCOL_NAME:
        raise InvalidTopicError("%r is not a Coaty topic" % (text[:120],))
    if levels[1] != str(PROTOCOL_VERSION):
        raise ProtocolVersionError("protocol version %r is not %d in %r"
                                   % (levels[1][:20], PROTOCOL_VERSION, text[:120]))
    event_level = levels[3]
    event, _, rest = event_level.partition(":")
    core_type = object_type = filt = None
    if rest:
        if event not in _FILTERED:
            raise InvalidTopicError("event %r takes no filter in %r" % (event, text[:120]))
        if event == "ADV" or event == "UPD":
            if rest.startswith(":"):
                object_type = rest[1:]
            else:
                core_type = rest
        else:
            filt = rest
    elif event in _FILTERED:
        raise InvalidTopicError("event %r needs a filter in %r" % (event, text[:120]))
    correlation_id = levels[5] if len(levels) == 6 else None
    if event in TWO_WAY and correlation_id is None:
        raise InvalidTopicError("two-way event %r without correlationId in %r" % (event, text[:120]))
    return Topic(namespace=levels[2], event=event, source_id=levels[4],
                 correlation_id=correlation_id, core_type=core_type,
                 object_type=object_type, filter=filt)


def resolve_subscription(namespace, correlation_id):
    """The Resolves to one of our Discovers only (any sender, any protocol version), as a Coaty agent subscribes:
    a wildcard on the correlation id brought every robot every Resolve of the fleet."""
    check_name(namespace, "namespace")
    check_name(correlation_id, "correlation id")
    return "%s/+/%s/RSV/+/%s" % (PROTOCOL_NAME, namespace, correlation_id)


def subscription(namespace, event_level, two_way=False):
    """The MQTT subscription filter for one event level of any protocol version and any
    sender (the version is a wildcard so that other versions are counted, not unseen)."""
    check_name(namespace, "namespace")
    return "%s/+/%s/%s/+%s" % (PROTOCOL_NAME, namespace, event_level, "/+" if two_way else "")
