"""LZF compression: hand-made vectors, round trips, corrupt streams."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skpcd.io._lzf import (
    LZFError,
    _compress_kernel,
    _decompress_kernel,
    lzf_compress,
    lzf_decompress,
)


@pytest.mark.parametrize(
    ("stream", "expected"),
    [
        (b"", b""),
        (b"\x00a", b"a"),
        (b"\x02abc", b"abc"),
        # literal "abc", then a back-reference of 4 + 2 bytes, offset 3
        (b"\x02abc\x80\x02", b"abcabcabc"),
        # overlapping reference (offset 1) repeats one byte: run-length
        (b"\x00z\xe0\x03\x00", b"z" * 13),
        # length 7 + extra byte 255 + 2 = 264, the longest reference
        (b"\x00q\xe0\xff\x00", b"q" * 265),
        # two literal runs in a row
        (b"\x01ab\x01cd", b"abcd"),
        # literal, reference, literal
        (b"\x01ab\x20\x01\x00c", b"ababac"),
    ],
)
def test_decompress_known_vectors(stream, expected):
    assert lzf_decompress(stream, len(expected)) == expected


def test_decompress_longest_offset():
    head = bytes(range(256)) * 32  # 8192 distinct-enough bytes
    # reference to the very first byte: offset 8191 + 1 = 8192
    stream = bytearray()
    for i in range(0, len(head), 32):
        stream += bytes([31]) + head[i : i + 32]
    stream += bytes([0x20 | 0x1F, 0xFF])  # length 1 + 2 = 3, offset 8192
    out = lzf_decompress(bytes(stream), len(head) + 3)
    assert out == head + head[:3]


@pytest.mark.parametrize(
    ("stream", "size", "message"),
    [
        (b"\x05abc", 6, "truncated"),  # literal run of 6, only 3 bytes
        (b"\x02abc\x80", 9, "truncated"),  # reference without its offset byte
        (b"\x02abc\xe0", 20, "truncated"),  # length 7 without its extra byte
        (b"\x02abc\x80\x05", 9, "before the start"),  # offset 6 > 3 written
        (b"\x20\x00", 3, "before the start"),  # reference with nothing written
        (b"\x02abc\x80\x02", 5, "more than the expected 5"),  # output overflow
        (b"\x03abcd", 3, "more than the expected 3"),
        (b"\x02abc", 10, "decompresses to 3 bytes, expected 10"),
    ],
)
def test_decompress_corrupt_streams(stream, size, message):
    with pytest.raises(LZFError, match=message) as excinfo:
        lzf_decompress(stream, size)
    assert isinstance(excinfo.value, ValueError)


def test_decompress_random_garbage_never_crashes():
    rng = np.random.default_rng(0)
    for _ in range(300):
        stream = rng.integers(0, 256, rng.integers(1, 60), dtype=np.uint8).tobytes()
        size = int(rng.integers(0, 200))
        try:
            out = lzf_decompress(stream, size)
        except LZFError:
            continue
        assert len(out) == size


def test_decompress_negative_size():
    with pytest.raises(ValueError, match="expected_size"):
        lzf_decompress(b"", -1)


PATTERNS = {
    "empty": b"",
    "one": b"x",
    "two": b"xy",
    "three": b"xyz",
    "zeros": bytes(10000),
    "text": b"the quick brown fox jumps over the lazy dog " * 200,
    "random": np.random.default_rng(1).integers(0, 256, 5000, np.uint8).tobytes(),
    "small alphabet": np.random.default_rng(2)
    .integers(0, 3, 20000, np.uint8)
    .tobytes(),
    "floats": np.round(np.random.default_rng(3).normal(size=3000), 2)
    .astype(np.float32)
    .tobytes(),
    "long run then noise": bytes(70000)
    + np.random.default_rng(4).integers(0, 256, 100, np.uint8).tobytes(),
}


@pytest.mark.parametrize("name", list(PATTERNS))
def test_round_trip(name):
    data = PATTERNS[name]
    packed = lzf_compress(data)
    assert len(packed) <= len(data) + len(data) // 32 + 1
    assert lzf_decompress(packed, len(data)) == data


def test_compression_actually_compresses():
    assert len(lzf_compress(bytes(100000))) < 100000 // 264 * 3 + 10
    text = PATTERNS["text"]
    assert len(lzf_compress(text)) < len(text) // 10


def test_compress_accepts_bytes_like():
    data = b"abcabcabcabc" * 10
    expected = lzf_compress(data)
    assert lzf_compress(bytearray(data)) == expected
    assert lzf_compress(memoryview(data)) == expected
    assert lzf_compress(np.frombuffer(data, np.uint8)) == expected
    assert lzf_decompress(bytearray(expected), len(data)) == data


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=3000))
def test_round_trip_hypothesis(data):
    assert lzf_decompress(lzf_compress(data), len(data)) == data


@settings(max_examples=100, deadline=None)
@given(
    st.lists(st.sampled_from([b"ab", b"abc", b"\x00" * 7, b"xyzw", b"q"]), max_size=400)
)
def test_round_trip_repetitive_hypothesis(chunks):
    data = b"".join(chunks)
    assert lzf_decompress(lzf_compress(data), len(data)) == data


def test_pure_python_kernels_agree():
    """The kernels also run uncompiled (the fallback without numba)."""
    data = PATTERNS["small alphabet"][:3000] + PATTERNS["text"][:2000]
    src = np.frombuffer(data, np.uint8)
    dst = np.empty(len(data) + len(data) // 32 + 16, np.uint8)
    table = np.full(1 << 16, -1, np.int64)
    compress = getattr(_compress_kernel, "py_func", _compress_kernel)
    size = compress(src, dst, table)
    assert dst[:size].tobytes() == lzf_compress(data)
    decompress = getattr(_decompress_kernel, "py_func", _decompress_kernel)
    out = np.empty(len(data), np.uint8)
    assert decompress(dst[:size], out, np.zeros(1, np.int64)) == len(data)
    assert out.tobytes() == data


def test_cross_check_with_liblzf():
    lzf = pytest.importorskip("lzf")  # python-lzf, a binding of liblzf
    for data in PATTERNS.values():
        if not data:
            continue
        assert lzf.decompress(lzf_compress(data), len(data)) == data
        theirs = lzf.compress(data)
        if theirs is not None:  # None when liblzf cannot make it smaller
            assert lzf_decompress(theirs, len(data)) == data
