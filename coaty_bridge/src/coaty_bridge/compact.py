"""Compact encoding of a cell index set: sorted, delta, LEB128 varint, base64.

The set is sorted and deduplicated; the first varint is the smallest index, each
further varint the (positive) gap to the previous one. The bytes are base64
(RFC 4648, with padding), so the result is a plain JSON string that any Coaty
agent carries untouched. Cells of one obstacle are close together, so most gaps
fit in one or two bytes where a decimal index costs six to eight.

When raw DEFLATE (RFC 1951) makes the varint bytes shorter, the string is
``"z:" + base64(deflate(varints))`` instead; gaps repeat a lot (runs of 1, the
same row jump), so this usually halves the size. Node decodes it with
``zlib.inflateRawSync``. Decoding bounds the inflated size (no zip bombs).
"""
import base64
import binascii
import zlib

from coaty_bridge.errors import OutOfRangeError, TooManyIndexesError, WrongTypeError

MAX_INDEX = 2 ** 32 - 1  # uint32 cell index
_MAX_VARINT_BYTES = 5


def encode_indexes(indexes):
    """Encodes an iterable of non-negative ints (< 2**32) as a base64 string."""
    out = bytearray()
    previous = None
    for value in sorted(set(indexes)):
        if not 0 <= value <= MAX_INDEX:
            raise ValueError("index %r outside 0..%d" % (value, MAX_INDEX))
        delta = value if previous is None else value - previous
        previous = value
        while True:
            byte = delta & 0x7F
            delta >>= 7
            if delta:
                out.append(byte | 0x80)
            else:
                out.append(byte)
                break
    raw = bytes(out)
    deflater = zlib.compressobj(9, zlib.DEFLATED, -15)
    packed = deflater.compress(raw) + deflater.flush()
    if len(packed) + 2 < len(raw):
        return "z:" + base64.b64encode(packed).decode("ascii")
    return base64.b64encode(raw).decode("ascii")


def decode_indexes(text, limit, max_count):
    """Decodes a string from encode_indexes into a sorted tuple of ints.

    Every index must be < ``limit`` (the grid size) and there may be at most
    ``max_count`` of them; raises an InvalidPayloadError subclass otherwise.
    """
    if not isinstance(text, str):
        raise WrongTypeError("compact indexes %r are not a string" % (str(text)[:40],))
    max_bytes = _MAX_VARINT_BYTES * max_count
    deflated = text.startswith("z:")
    body = text[2:] if deflated else text
    if len(body) > 4 * ((max_bytes + 2) // 3) + 4:
        raise TooManyIndexesError("compact indexes of %d characters exceed %d indexes"
                                  % (len(text), max_count))
    try:
        data = base64.b64decode(body.encode("ascii"), validate=True)
    except (binascii.Error, UnicodeEncodeError, ValueError) as err:
        raise WrongTypeError("compact indexes %r are not base64 (%s)" % (text[:40], err))
    if deflated:
        inflater = zlib.decompressobj(-15)
        try:
            data = inflater.decompress(data, max_bytes + 1)
        except zlib.error as err:
            raise WrongTypeError("compact indexes %r are not raw deflate (%s)" % (text[:40], err))
        if len(data) > max_bytes or inflater.unconsumed_tail:
            raise TooManyIndexesError("deflated compact indexes inflate beyond %d indexes" % max_count)
        if not inflater.eof:
            raise OutOfRangeError("deflated compact indexes %r are truncated" % (text[:40],))
    result = []
    value = None
    delta = shift = used = 0
    for byte in data:
        delta |= (byte & 0x7F) << shift
        shift += 7
        used += 1
        if used > _MAX_VARINT_BYTES:
            raise OutOfRangeError("compact indexes: varint longer than %d bytes" % _MAX_VARINT_BYTES)
        if byte & 0x80:
            continue
        if value is not None and delta == 0:
            raise OutOfRangeError("compact indexes: repeated index %d" % value)
        value = delta if value is None else value + delta
        if value >= limit:
            raise OutOfRangeError("compact index %d outside the grid (size %d)" % (value, limit))
        if len(result) >= max_count:
            raise TooManyIndexesError("more than %d compact indexes" % max_count)
        result.append(value)
        delta = shift = used = 0
    if used:
        raise OutOfRangeError("compact indexes end inside a varint")
    return tuple(result)
