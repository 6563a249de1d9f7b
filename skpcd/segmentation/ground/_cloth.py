"""CSF on a scene seen in chunks: one cloth for the whole scene, bit for bit.

The reference CSF sees the points through its rasterisation only: each
cloth particle takes the height of the point nearest to it (the first of
equally near ones), the cloth's frame is the points' bounding box, and the
simulation runs on the particles. So the cloth of a scene is the cloth of a
much smaller cloud: the nearest point of every particle, the points that
set the bounding box, and the fill points of
:func:`~skpcd.segmentation.ground._csf._far_fill`. :class:`StreamedCloth`
gathers that cloud in passes over chunks of the scene (memory: the
particles, not the points), runs the reference simulation on it, and then
tests each chunk's points against the cloth as CSF's ``c2cdist`` does
(:mod:`~skpcd.segmentation.ground._cloth_kernels`). Groups of points far
apart get a cloth each, as in :func:`~skpcd.segmentation.ground._csf.csf_ground`.
The flags are those of :func:`~skpcd.segmentation.ground._csf.csf_ground`
on the whole scene (``tests/segmentation/test_cloth.py`` compares them on
real scans).
"""

import numpy as np

from skpcd.segmentation.ground._cloth_kernels import classify_points, sample_points
from skpcd.segmentation.ground._csf import (
    ISLAND_CELLS,
    MIN_ISLAND_POINTS,
    fill_points,
    simulate_cloth,
)
from skpcd.segmentation.ground._raster import MAX_CELLS, islands
from skpcd.segmentation.ground._raster_kernels import cell_indices_rows

__all__ = ["StreamedCloth"]


class StreamedCloth:
    """The cloth of CSF over a scene given chunk by chunk.

    Use: construct with the scene's exact bounds and point count; if
    :attr:`needs_cells`, :meth:`add_cells` every chunk; then :meth:`sample`
    every chunk (with the points' scan indices); :meth:`simulate`; then
    :meth:`classify` any chunk. Chunks may come in any order and sizes.

    Parameters
    ----------
    params : dict
        ``cloth_resolution``, ``class_threshold``, ``rigidness``,
        ``slope_smooth``, ``iterations``, ``time_step`` (as
        :func:`~skpcd.segmentation.ground._csf.csf_ground`).
    mins, maxs : ndarray of shape (3,)
        Exact bounds of the scene's points.
    n_points : int
        Points in the scene.
    """

    def __init__(self, params, mins, maxs, n_points):
        self.params = dict(params)
        self.res = float(params["cloth_resolution"])
        self.lo = np.asarray(mins, dtype=np.float64)[:2].copy()
        extent = np.asarray(maxs, dtype=np.float64)[:2] - self.lo
        self.nx, self.ny = (int(v) for v in np.floor(extent / self.res) + 1)
        # one group for the scene, as csf_ground, unless its raster is much
        # larger than its points: then the islands of occupied cells
        self.needs_cells = self.nx * self.ny > max(int(n_points), 4 * ISLAND_CELLS**2)
        self._cells = []  # per chunk: (keys, min xyz, max xy, count)
        if not self.needs_cells:
            self._set_groups(
                np.asarray(mins, dtype=np.float64)[None],
                np.asarray(maxs, dtype=np.float64)[None, :2],
            )

    # -- pass 1: the occupied cells (only for a scene of islands) ----------

    def _keys(self, xyz):
        cells = np.empty((len(xyz), 2), dtype=np.int64)
        cell_indices_rows(
            0, len(xyz), xyz, self.lo[0], self.lo[1], self.res, self.nx, self.ny,
            cells,
        )  # fmt: skip
        return cells[:, 0] * self.ny + cells[:, 1]

    def add_cells(self, xyz):
        """Fold a chunk into the table of occupied cells.

        Parameters
        ----------
        xyz : ndarray of shape (n, 3)
            Points of the scene (each point in exactly one chunk).
        """
        if not len(xyz):
            return
        self._cells.append(_cell_table(self._keys(xyz), xyz))
        if len(self._cells) >= 16:
            self._cells = [_merge_tables(self._cells)]

    def _finish_cells(self):
        keys, lo, hi, count = _merge_tables(self._cells)
        self._cells = []
        cells = np.column_stack([keys // self.ny, keys % self.ny])
        _, label = islands(cells, ISLAND_CELLS)
        n_isl = int(label.max()) + 1
        mins = np.full((n_isl, 3), np.inf)
        maxs = np.full((n_isl, 2), -np.inf)
        np.minimum.at(mins, label, lo)
        np.maximum.at(maxs, label, hi)
        counts = np.bincount(label, weights=count, minlength=n_isl)
        big = counts >= MIN_ISLAND_POINTS
        group_of = np.where(big, np.cumsum(big) - 1, -2)
        self._keys_sorted = keys
        self._cell_group = group_of[label]
        self._set_groups(mins[big], maxs[big])

    def _set_groups(self, mins, maxs):
        res = self.res
        self.shift = np.ascontiguousarray(mins)
        extent = maxs - mins[:, :2]
        z_w = (np.floor(extent[:, 0] / res) + 1).astype(np.int64)
        z_h = (np.floor(extent[:, 1] / res) + 1).astype(np.int64)
        p_w, p_h = z_w + 5, z_h + 5  # particles: the fill may reach half a cell out
        if int((p_w * p_h).sum()) > MAX_CELLS:
            raise ValueError(
                f"the occupied part of the scene needs {int((p_w * p_h).sum())} "
                f"cloth particles of {res} (more than {MAX_CELLS}); use a larger "
                "cell"
            )
        self.z_w, self.z_h = z_w, z_h
        self.z_start = np.r_[0, np.cumsum(z_w * z_h)[:-1]].astype(np.int64)
        self.p_w, self.p_h = p_w, p_h
        self.p_start = np.r_[0, np.cumsum(p_w * p_h)[:-1]].astype(np.int64)
        n_p = int((p_w * p_h).sum())
        self.zmin = np.full(int((z_w * z_h).sum()), np.inf)
        self.best_d = np.full(n_p, np.inf)
        self.best_i = np.full(n_p, np.iinfo(np.int64).max, dtype=np.int64)
        self.best_xyz = np.zeros((n_p, 3))
        k = len(mins)
        self.extreme_v = np.full((k, 5), np.inf)
        self.extreme_i = np.full((k, 5), np.iinfo(np.int64).max, dtype=np.int64)
        self.extreme_xyz = np.zeros((k, 5, 3))

    def _groups(self, xyz):
        """Group of each point: its cloth, -2 for a group too small for one."""
        if not self.needs_cells:
            return np.zeros(len(xyz), dtype=np.int64)
        pos = np.searchsorted(self._keys_sorted, self._keys(xyz))
        return self._cell_group[pos]

    # -- pass 2: what the cloth sees ---------------------------------------

    def sample(self, xyz, index):
        """Fold a chunk into the particles' nearest points and the fill raster.

        Parameters
        ----------
        xyz : ndarray of shape (n, 3)
            Points of the scene.
        index : ndarray of shape (n,), dtype int64
            Their indices in the scan (the order CSF would see them in).
        """
        if self.needs_cells and self._cells:
            self._finish_cells()
        if not len(xyz):
            return
        sample_points(
            np.ascontiguousarray(xyz, dtype=np.float64), np.asarray(index, np.int64),
            self._groups(xyz), self.shift, self.res, self.zmin, self.z_start,
            self.z_w, self.z_h, self.best_d, self.best_i, self.best_xyz,
            self.p_start, self.p_w, self.extreme_v, self.extreme_i,
            self.extreme_xyz,
        )  # fmt: skip

    # -- the simulation ------------------------------------------------------

    def simulate(self):
        """Run the reference simulation of each group on what it saw."""
        clothes, starts, widths = [], [], []
        offset = 0
        for g in range(len(self.shift)):
            pts = self._reduced(g)
            cloth, width = simulate_cloth(pts, self.params)
            clothes.append(cloth)
            starts.append(offset)
            widths.append(width)
            offset += len(cloth)
        self.cloth = np.concatenate(clothes) if clothes else np.zeros(0)
        self.c_start = np.array(starts, dtype=np.int64)
        self.c_width = np.array(widths, dtype=np.int64)
        del self.best_d, self.best_xyz, self.zmin

    def _reduced(self, g):
        """The cloud whose cloth is group ``g``'s: its particles' nearest
        points and its extreme points in scan order, then its fill points."""
        a = self.p_start[g]
        b = a + int(self.p_w[g]) * int(self.p_h[g])
        taken = self.best_i[a:b] < np.iinfo(np.int64).max
        idx = np.concatenate([self.best_i[a:b][taken], self.extreme_i[g]])
        pts = np.concatenate([self.best_xyz[a:b][taken], self.extreme_xyz[g]])
        idx, first = np.unique(idx, return_index=True)
        pts = pts[first]
        za = self.z_start[g]
        zmin = self.zmin[za : za + self.z_w[g] * self.z_h[g]].reshape(
            self.z_h[g], self.z_w[g]
        )
        fill = fill_points(zmin, self.res)
        return np.vstack([pts, fill]) if len(fill) else pts

    # -- pass 3: the test of every point -----------------------------------

    def classify(self, xyz):
        """CSF's ground flags of a chunk of the scene.

        Parameters
        ----------
        xyz : ndarray of shape (n, 3)
            Points of the scene.

        Returns
        -------
        ground : ndarray of shape (n,), dtype bool
        """
        out = np.zeros(len(xyz), dtype=bool)
        if len(xyz):
            classify_points(
                np.ascontiguousarray(xyz, dtype=np.float64), self._groups(xyz),
                self.shift, self.res, float(self.params["class_threshold"]),
                self.cloth, self.c_start, self.c_width, out,
            )  # fmt: skip
        return out


def _cell_table(keys, xyz):
    """Per occupied cell key: lowest x, y, z, highest x, y, point count."""
    order = np.argsort(keys, kind="stable")
    k = keys[order]
    starts = np.flatnonzero(np.r_[True, k[1:] != k[:-1]])
    pts = xyz[order]
    lo = np.minimum.reduceat(pts[:, :3], starts, axis=0)
    hi = np.maximum.reduceat(pts[:, :2], starts, axis=0)
    count = np.diff(np.r_[starts, len(k)])
    return k[starts], lo, hi, count


def _merge_tables(tables):
    keys = np.concatenate([t[0] for t in tables])
    lo = np.concatenate([t[1] for t in tables])
    hi = np.concatenate([t[2] for t in tables])
    count = np.concatenate([t[3] for t in tables])
    order = np.argsort(keys, kind="stable")
    k = keys[order]
    starts = np.flatnonzero(np.r_[True, k[1:] != k[:-1]])
    return (
        k[starts],
        np.minimum.reduceat(lo[order], starts, axis=0),
        np.maximum.reduceat(hi[order], starts, axis=0),
        np.add.reduceat(count[order], starts),
    )
