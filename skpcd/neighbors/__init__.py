"""Neighbour search: the grid of cells and the k-nearest and radius
neighbourhoods that descriptors, normals, sampling and segmentation share.

:func:`compute_neighborhoods` returns the neighbourhoods of every point of
a list of clouds, with PCL's order and tie rules; :class:`Neighborhoods`
holds them. Both are also importable from :mod:`skpcd.preprocessing`.
"""

from skpcd.neighbors._neighbors import Neighborhoods, compute_neighborhoods

__all__ = ["Neighborhoods", "compute_neighborhoods"]
