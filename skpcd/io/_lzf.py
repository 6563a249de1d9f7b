"""LZF compression in the liblzf format, as used by PCD ``binary_compressed``.

An LZF stream is a sequence of chunks, each starting with a control byte
``ctrl``:

- ``ctrl < 32``: a literal run; the next ``ctrl + 1`` bytes are copied to the
  output as they are.
- ``ctrl >= 32``: a back-reference. Its length field is ``ctrl >> 5``; the
  value 7 means that one more byte follows and is added to it. Then comes one
  byte ``b``; the reference copies ``length + 2`` bytes starting
  ``((ctrl & 0x1f) << 8) + b + 1`` bytes before the current end of the output
  (the source may overlap the bytes being written, which repeats them).

The stream has no header: the caller must know the decompressed size (PCD
stores it next to the compressed size). :func:`lzf_compress` is a greedy
hash-table compressor like liblzf's, so its output is decodable by liblzf,
PCL and :func:`lzf_decompress`. Both loops are compiled with numba.
"""

import numpy as np

try:
    from numba import njit
except ImportError:  # pragma: no cover - numba comes with pynndescent

    def njit(*args, **kwargs):
        return lambda func: func


__all__ = ["LZFError", "lzf_compress", "lzf_decompress"]

_MAX_LITERAL = 32  # longest literal run
_MAX_OFFSET = 1 << 13  # furthest back-reference
_MAX_MATCH = (1 << 8) + (1 << 3)  # longest back-reference: 7 + 255 + 2 bytes
_HASH_BITS = 16

# Error codes returned by the decompression kernel.
_TRUNCATED = -1
_OVERFLOW = -2
_BEFORE_START = -3


class LZFError(ValueError):
    """An LZF stream is corrupt or does not decompress to the expected size."""


@njit(cache=True, nogil=True)
def _decompress_kernel(src, dst, where):
    """Decode ``src`` into ``dst``; the output length, or a negative error code.

    On error ``where[0]`` is the offset in ``src`` of the faulty chunk.
    """
    n_in = src.shape[0]
    n_out = dst.shape[0]
    ip = 0
    op = 0
    while ip < n_in:
        where[0] = ip
        ctrl = int(src[ip])
        ip += 1
        if ctrl < 32:
            length = ctrl + 1
            if ip + length > n_in:
                return _TRUNCATED
            ref = -1  # not read: a literal run copies from src
        else:
            length = ctrl >> 5
            if length == 7:
                if ip >= n_in:
                    return _TRUNCATED
                length += int(src[ip])
                ip += 1
            if ip >= n_in:
                return _TRUNCATED
            ref = op - ((ctrl & 0x1F) << 8) - int(src[ip]) - 1
            ip += 1
            length += 2
            if ref < 0:
                return _BEFORE_START
        # both kinds of chunk: room in the output, then the copy
        if op + length > n_out:
            return _OVERFLOW
        if ctrl < 32:
            for k in range(length):
                dst[op + k] = src[ip + k]
            ip += length
        else:
            for k in range(length):
                dst[op + k] = dst[ref + k]
        op += length
    return op


@njit(cache=True, nogil=True)
def _hash3(src, i):
    value = (int(src[i]) << 16) | (int(src[i + 1]) << 8) | int(src[i + 2])
    return ((value * 2654435761) & 0xFFFFFFFF) >> (32 - 16)


@njit(cache=True, nogil=True)
def _compress_kernel(src, dst, table):
    """Greedy LZF compression of ``src`` into ``dst``; returns the output length.

    ``table`` (``2**16`` int64, filled with -1) maps a hash of three bytes to
    the last input position where they were seen. ``dst`` must hold at least
    ``len(src) + len(src) // 32 + 16`` bytes.
    """
    n = src.shape[0]
    ip = 0
    op = 1  # dst[0] is kept for the control byte of the first literal run
    lit = 0
    while ip < n:
        length = off = 0
        if ip < n - 2:  # a back-reference needs three bytes
            h = _hash3(src, ip)
            ref = table[h]
            table[h] = ip
            off = ip - ref - 1
            if (
                ref >= 0
                and off < 8192
                and src[ref] == src[ip]
                and src[ref + 1] == src[ip + 1]
                and src[ref + 2] == src[ip + 2]
            ):
                max_len = min(n - ip, 264)
                length = 3
                while length < max_len and src[ref + length] == src[ip + length]:
                    length += 1
        if length:
            # Close the pending literal run, or drop its unused control byte.
            if lit:
                dst[op - lit - 1] = lit - 1
            else:
                op -= 1
            code = length - 2
            if code < 7:
                dst[op] = (off >> 8) + (code << 5)
                op += 1
            else:
                dst[op] = (off >> 8) + (7 << 5)
                dst[op + 1] = code - 7
                op += 2
            dst[op] = off & 0xFF
            op += 2  # the offset byte, then room for the next run's control byte
            lit = 0
            end = ip + length
            ip += 1
            while ip < end and ip < n - 2:
                table[_hash3(src, ip)] = ip
                ip += 1
            ip = end
        else:
            dst[op] = src[ip]
            op += 1
            ip += 1
            lit += 1
            if lit == 32:
                dst[op - lit - 1] = lit - 1
                lit = 0
                op += 1
    if lit:
        dst[op - lit - 1] = lit - 1
    else:
        op -= 1
    return op


def _as_uint8(data):
    try:
        return np.frombuffer(data, dtype=np.uint8)
    except (TypeError, ValueError):
        return np.frombuffer(bytes(data), dtype=np.uint8)


def lzf_decompress_array(data, expected_size):
    """Like :func:`lzf_decompress`, but returns a writable uint8 array."""
    src = _as_uint8(data)
    expected_size = int(expected_size)
    if expected_size < 0:
        raise ValueError(f"expected_size must be >= 0, got {expected_size}")
    dst = np.empty(expected_size, dtype=np.uint8)
    where = np.zeros(1, dtype=np.int64)
    size = _decompress_kernel(src, dst, where)
    at = int(where[0])
    if size == _TRUNCATED:
        raise LZFError(
            f"the LZF stream is truncated: the chunk at byte {at} of {len(src)} "
            "runs past its end."
        )
    if size == _OVERFLOW:
        raise LZFError(
            f"the LZF stream decompresses to more than the expected {expected_size} "
            f"bytes (at byte {at} of the stream)."
        )
    if size == _BEFORE_START:
        raise LZFError(
            f"the LZF stream is corrupt: the back-reference at byte {at} points "
            "before the start of the output."
        )
    if size != expected_size:
        raise LZFError(
            f"the LZF stream decompresses to {size} bytes, expected {expected_size}."
        )
    return dst


def lzf_decompress(data, expected_size):
    """Decompress an LZF stream (liblzf format).

    Parameters
    ----------
    data : bytes-like
        The compressed stream.
    expected_size : int
        The exact size of the decompressed data.

    Returns
    -------
    bytes
        The decompressed data, ``expected_size`` bytes long.

    Raises
    ------
    LZFError
        A :class:`ValueError` if the stream is truncated, holds a
        back-reference before the start of the output, or decompresses to
        another size than ``expected_size``.

    Examples
    --------
    >>> from skpcd.io._lzf import lzf_compress, lzf_decompress
    >>> data = b"abcabcabcabcabcabc"
    >>> lzf_decompress(lzf_compress(data), len(data)) == data
    True
    >>> lzf_decompress(b"\\x02abc\\x80\\x02", 9)
    b'abcabcabc'
    """
    return lzf_decompress_array(data, expected_size).tobytes()


def lzf_compress(data):
    """Compress bytes into an LZF stream (liblzf format).

    Parameters
    ----------
    data : bytes-like
        The data to compress.

    Returns
    -------
    bytes
        The stream; at most ``len(data) + len(data) // 32 + 1`` bytes long
        (incompressible data grows by one control byte per 32 bytes). Empty
        input gives an empty stream.

    Examples
    --------
    >>> from skpcd.io._lzf import lzf_compress
    >>> len(lzf_compress(bytes(1000))) < 30
    True
    """
    src = _as_uint8(data)
    n = len(src)
    if n == 0:
        return b""
    dst = np.empty(n + n // _MAX_LITERAL + 16, dtype=np.uint8)
    table = np.full(1 << _HASH_BITS, -1, dtype=np.int64)
    size = _compress_kernel(src, dst, table)
    return dst[:size].tobytes()
