"""Small pictures of a segment: a top and a side view coloured by height.

The points are rasterised with numpy into an image of palette indices
(index 0: empty, transparent; 1-255: height, low to high) and encoded as a
palette PNG with :mod:`zlib`: no plotting library is imported, and a
96-pixel view of a segment of any size is a few kilobytes.
"""

import base64
import struct
import zlib

import numpy as np

__all__ = ["HEIGHT_PALETTE", "encode_png", "render_views", "view_data_uris"]

# viridis at nine stops (low: dark purple, high: yellow)
_STOPS = np.array(
    [
        [68, 1, 84],
        [71, 44, 122],
        [59, 81, 139],
        [44, 113, 142],
        [33, 144, 141],
        [39, 173, 129],
        [92, 200, 99],
        [170, 220, 50],
        [253, 231, 37],
    ],
    dtype=float,
)


def _height_palette():
    """256 RGB colours: index 0 white (transparent in the PNG), 1-255 the
    height ramp."""
    t = np.linspace(0.0, 1.0, 255) * (len(_STOPS) - 1)
    lo = np.minimum(t.astype(int), len(_STOPS) - 2)
    frac = (t - lo)[:, None]
    ramp = _STOPS[lo] * (1 - frac) + _STOPS[lo + 1] * frac
    palette = np.vstack([[255, 255, 255], ramp])
    return np.round(palette).astype(np.uint8)


#: ndarray of uint8 of shape (256, 3): the colours of the palette indices.
HEIGHT_PALETTE = _height_palette()


def _chunk(kind, data):
    body = kind + data
    return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body))


def encode_png(indices, palette=HEIGHT_PALETTE, *, transparent=0):
    """Encode an image of palette indices as an 8-bit palette PNG.

    Parameters
    ----------
    indices : ndarray of uint8 of shape (height, width)
        The palette index of each pixel, first row at the top.
    palette : ndarray of uint8 of shape (n_colours, 3), default=HEIGHT_PALETTE
        The RGB colour of each index (at most 256).
    transparent : int or None, default=0
        The index drawn transparent; None: none.

    Returns
    -------
    png : bytes
        The PNG file.

    Examples
    --------
    >>> import numpy as np
    >>> from skpcd.io._thumbnails import encode_png
    >>> png = encode_png(np.zeros((2, 3), dtype=np.uint8))
    >>> png[:8] == b"\\x89PNG\\r\\n\\x1a\\n"
    True
    """
    indices = np.ascontiguousarray(indices, dtype=np.uint8)
    height, width = indices.shape
    palette = np.asarray(palette, dtype=np.uint8)
    # filter type 0 (none) before each row
    raw = np.zeros((height, width + 1), dtype=np.uint8)
    raw[:, 1:] = indices
    header = struct.pack(">IIBBBBB", width, height, 8, 3, 0, 0, 0)
    parts = [
        b"\x89PNG\r\n\x1a\n",
        _chunk(b"IHDR", header),
        _chunk(b"PLTE", palette.tobytes()),
    ]
    if transparent is not None:
        alpha = np.full(transparent + 1, 255, dtype=np.uint8)
        alpha[transparent] = 0
        parts.append(_chunk(b"tRNS", alpha.tobytes()))
    parts.append(_chunk(b"IDAT", zlib.compress(raw.tobytes(), 9)))
    parts.append(_chunk(b"IEND", b""))
    return b"".join(parts)


def _rasterise(u, v, key, colour, size, splat, span):
    """Pixels at ``(u, v)`` (v up), ``span`` metres across the image on both
    axes, centred, the point of highest ``key`` drawn where several fall in
    one pixel."""
    image = np.zeros((size, size), dtype=np.uint8)
    if len(u) == 0:
        return image
    lo_u, lo_v = u.min(), v.min()
    span = max(span, 1e-9)
    inner = size - splat
    scale = inner / span
    # centred on the shorter axis
    off_u = (inner - np.ptp(u) * scale) / 2
    off_v = (inner - np.ptp(v) * scale) / 2
    col = np.clip((u - lo_u) * scale + off_u, 0, inner - 1e-6).astype(np.intp)
    row = np.clip((v - lo_v) * scale + off_v, 0, inner - 1e-6).astype(np.intp)
    row = size - splat - row  # first row at the top
    for dr in range(splat):
        for dc in range(splat):
            pix = (row + dr) * size + (col + dc)
            order = np.lexsort((key, pix))
            pix_sorted = pix[order]
            last = np.ones(len(pix_sorted), dtype=bool)
            last[:-1] = pix_sorted[1:] != pix_sorted[:-1]
            image.flat[pix_sorted[last]] = colour[order[last]]
    return image


def render_views(points, size=96):
    """A top and a side view of a segment, as palette-index images.

    The colour is the height within the segment (index 1 at its lowest
    point, 255 at its highest). The top view looks down (x right, y up),
    the highest point of each pixel in front; the side view looks across
    the segment's main horizontal direction (the first principal axis of
    its x, y), so that it shows its widest side, the nearest point in
    front. Both views have one scale, equal on both axes: the largest
    extent of the segment fills the image (a pole is a dot from above and
    a line the image's height from the side).

    Parameters
    ----------
    points : array-like of shape (n_points, 3)
        The segment.
    size : int, default=96
        Width and height of each view in pixels.

    Returns
    -------
    top : ndarray of uint8 of shape (size, size)
        The top view (0 where no point falls).
    side : ndarray of uint8 of shape (size, size)
        The side view.

    Examples
    --------
    >>> import numpy as np
    >>> from skpcd.io._thumbnails import render_views
    >>> pole = np.column_stack([np.zeros(50), np.zeros(50), np.linspace(0, 5, 50)])
    >>> top, side = render_views(pole, size=16)
    >>> int((top > 0).sum()) <= 4, int((side > 0).sum()) >= 16
    (True, True)
    """
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    points = points[np.isfinite(points).all(axis=1)]
    if len(points) == 0:
        empty = np.zeros((size, size), dtype=np.uint8)
        return empty, empty.copy()
    z = points[:, 2]
    colour = (1 + np.round((z - z.min()) / max(np.ptp(z), 1e-9) * 254)).astype(np.uint8)
    # sparse segments: 2x2 dots, so that they stay visible
    splat = 2 if len(points) < size * size // 4 else 1
    xy = points[:, :2] - points[:, :2].mean(axis=0)
    axis = np.array([1.0, 0.0])
    if len(points) > 2:
        _, vectors = np.linalg.eigh(np.cov(xy.T))
        axis = vectors[:, -1]
    along = xy @ axis
    across = xy @ np.array([-axis[1], axis[0]])
    # one scale for both views: the largest extent fills the image
    span = max(np.ptp(xy[:, 0]), np.ptp(xy[:, 1]), np.ptp(z), np.ptp(along))
    top = _rasterise(points[:, 0], points[:, 1], z, colour, size, splat, span)
    side = _rasterise(along, z, -across, colour, size, splat, span)
    return top, side


def view_data_uris(points, size=96):
    """The views of :func:`render_views` as ``data:image/png;base64`` URIs.

    Parameters
    ----------
    points, size
        As for :func:`render_views`.

    Returns
    -------
    top, side : str
        The two views, ready for an ``<img src>``.
    """
    return tuple(
        "data:image/png;base64," + base64.b64encode(encode_png(view)).decode("ascii")
        for view in render_views(points, size)
    )
