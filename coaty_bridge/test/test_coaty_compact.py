import json
import random

import pytest
from hypothesis import given, settings, strategies as st

from coaty_bridge.compact import MAX_INDEX, decode_indexes, encode_indexes
from coaty_bridge.errors import InvalidPayloadError, OutOfRangeError, TooManyIndexesError


@settings(max_examples=300, derandomize=True)
@given(st.sets(st.integers(min_value=0, max_value=MAX_INDEX), max_size=300))
def test_round_trip_of_any_index_set(values):
    assert decode_indexes(encode_indexes(values), MAX_INDEX + 1, 1000) == tuple(sorted(values))


def test_known_encoding():
    # 0 -> 00; gap 1 -> 01; gap 300 -> ac 02
    assert encode_indexes([301, 0, 1]) == "AAGsAg=="
    assert decode_indexes("AAGsAg==", 1000, 10) == (0, 1, 301)
    assert encode_indexes([]) == ""


@pytest.mark.parametrize("text, error", [
    ("AAA=", OutOfRangeError),         # gap 0: a repeated index
    ("gA==", OutOfRangeError),         # ends inside a varint
    ("//////8P", OutOfRangeError),     # varint longer than 5 bytes
    ("AAGsAg==", OutOfRangeError),     # 301 outside a grid of 300 cells
    ("not base64", InvalidPayloadError),
])
def test_bad_compact_strings_raise(text, error):
    with pytest.raises(error):
        decode_indexes(text, 300, 100)


def test_repetitive_sets_are_deflated_and_decode_the_same():
    cells = list(range(5000, 5300)) + list(range(9000, 9300, 3))
    text = encode_indexes(cells)
    assert text.startswith("z:") and len(text) < 60
    assert decode_indexes(text, 10000, 1000) == tuple(sorted(cells))


def test_deflate_bombs_and_broken_streams_are_rejected():
    import base64
    import zlib
    deflater = zlib.compressobj(9, zlib.DEFLATED, -15)
    bomb = deflater.compress(b"\x01" * 10 ** 6) + deflater.flush()
    with pytest.raises(TooManyIndexesError):
        decode_indexes("z:" + base64.b64encode(bomb).decode(), 2 ** 32, 100)
    good = encode_indexes(range(0, 600, 2))
    with pytest.raises(InvalidPayloadError):
        decode_indexes(good[:-8], 10000, 1000)
    with pytest.raises(InvalidPayloadError):
        decode_indexes("z:AAAA", 10000, 1000)


def test_count_limit_is_enforced_before_and_while_decoding():
    text = encode_indexes(range(50))
    assert len(decode_indexes(text, 100, 50)) == 50
    with pytest.raises(TooManyIndexesError):
        decode_indexes(text, 100, 49)
    with pytest.raises(TooManyIndexesError):
        decode_indexes("A" * 10000, 100, 10)


def test_a_200_cell_obstacle_costs_under_a_third_of_a_plain_list():
    rng = random.Random(4)
    size_x = 2000
    cells = set()
    while len(cells) < 200:  # a blob in a 30 x 30 cell box in the middle of a 2000 x 2000 map
        cells.add((1000 + rng.randrange(30)) * size_x + 1000 + rng.randrange(30))
    plain = len(json.dumps(sorted(cells), separators=(",", ":")))
    packed = len(json.dumps(encode_indexes(cells)))
    assert packed * 3 <= plain, (packed, plain)
