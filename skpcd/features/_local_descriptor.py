"""What the PFH and FPFH share: the base of their transformers, and the
checks of their function forms' input.

:class:`_LocalDescriptor` takes a list of clouds, searches neighbourhoods
once, estimates normals and runs a subclass's kernels over all points of all
clouds (:class:`~skpcd.features.PFHTransformer`,
:class:`~skpcd.features.FPFHTransformer`); :func:`_as_f32` and
:func:`_neighborhoods` prepare the one cloud of
:func:`~skpcd.features.compute_pfh` and :func:`~skpcd.features.compute_fpfh`.
"""

import typing
from numbers import Integral, Real

import numpy as np
from sklearn.utils._param_validation import Interval, StrOptions

from skpcd.features._descriptor import FeatureNamesMixin, numbered
from skpcd.neighbors._neighbors import (
    Neighborhoods,
    compute_neighborhoods,
    scattered,
)
from skpcd.preprocessing._normals import (
    CLOUD_VIEWPOINT,
    check_viewpoint,
    local_viewpoints,
    normals_f32,
    pack_neighborhoods,
)
from skpcd.utils import check_point_clouds
from skpcd.utils._estimator import CloudTransformer
from skpcd.utils._geometry import local_frame
from skpcd.utils._memory import release_free_memory, unshared_zeros
from skpcd.utils._parallel import map_batches
from skpcd.utils._validation import (
    NORMALS_OPTIONS,
    check_given_normals,
    check_unit_normals,
    has_normal_columns,
)


def _as_f32(points, normals, neighborhoods):
    """The cloud in its local frame (float32) and the normals, checked."""
    xyz = np.ascontiguousarray(np.asarray(points)[:, :3], dtype=np.float64)
    p, _ = local_frame(xyz, np.array([0, len(xyz)]), input_name="points")
    n = np.ascontiguousarray(normals, dtype=np.float32)
    if n.shape != p.shape:
        raise ValueError(f"normals must have shape {p.shape}, got {n.shape}")
    check_unit_normals(n)
    if not isinstance(neighborhoods, Neighborhoods):
        raise TypeError("neighborhoods must come from compute_neighborhoods")
    if neighborhoods.n_points != len(p):
        raise ValueError(
            f"neighborhoods cover {neighborhoods.n_points} points, "
            f"the cloud has {len(p)}"
        )
    return p, n


def _neighborhoods(points, neighborhoods, n_neighbors, radius, n_threads):
    if neighborhoods is not None:
        return neighborhoods
    return compute_neighborhoods(
        points, n_neighbors=n_neighbors, radius=radius, n_jobs=n_threads
    )


# Points per part of a pooled transform (whole clouds; a larger cloud is a
# part of its own): the parts share one output buffer.
_POOLED_PART = 1 << 18


class _LocalDescriptor(FeatureNamesMixin, CloudTransformer):
    """Shared machinery of the per-point histogram transformers."""

    _parameter_constraints: typing.ClassVar[dict] = {
        "n_neighbors": [Interval(Integral, 2, None, closed="left"), None],
        "radius": [Interval(Real, 0, None, closed="neither"), None],
        "n_bins": [Interval(Integral, 2, None, closed="left")],
        "normals": [StrOptions(set(NORMALS_OPTIONS))],
        "normal_n_neighbors": [Interval(Integral, 3, None, closed="left"), None],
        "normal_radius": [Interval(Real, 0, None, closed="neither"), None],
        "viewpoint": ["array-like", StrOptions({CLOUD_VIEWPOINT})],
        "undefined": [StrOptions({"nan", "zero", "drop", "keep"})],
        "pooling": [StrOptions({"mean", "sum", "max"}), None],
        "n_jobs": [Integral, None],
    }
    _default_n_neighbors = 10
    # clouds whose neighbours lie far apart in memory (shuffled) computed in
    # the search's grid order (`scattered`): FPFH on the DALES objects as one
    # shuffled cloud 1.38-1.52x faster (benchmarks/bench_point_order.py);
    # clouds in recorded order are left in theirs (renumbering them anyway was
    # slower in three runs of four). PFH's pair stage is bound by its
    # arithmetic, not by its reads (1.2-1.4x slower shuffled): not renumbered.
    # Only a stage that writes its rows through `rows` may set this
    _grid_order = False

    def _check_search(self):
        if self.n_neighbors is not None and self.radius is not None:
            raise ValueError(
                "give n_neighbors or radius, not both "
                f"(n_neighbors={self.n_neighbors}, radius={self.radius})"
            )
        if self.normal_n_neighbors is not None and self.normal_radius is not None:
            raise ValueError("give normal_n_neighbors or normal_radius, not both")
        check_viewpoint(self.viewpoint)

    @property
    def _bounded_batches(self):
        # pooled: one row per cloud, so the per-point rows of one batch at a
        # time, not of all clouds, are held (bounded memory)
        return self.pooling is not None

    def _validate(self, X):
        self._check_search()
        clouds = check_point_clouds(X, ensure_all_finite=False)
        for i, c in enumerate(clouds):
            if not np.isfinite(c[:, :3]).all():
                raise ValueError(f"X[{i}] has NaN or infinite coordinates.")
        check_given_normals(clouds, self.normals, estimation=self._estimation_set())
        return clouds

    def _estimation_set(self):
        """The parameters of the normal estimation set away from their default."""
        names = [
            name
            for name in ("normal_n_neighbors", "normal_radius")
            if getattr(self, name) is not None
        ]
        if not isinstance(check_viewpoint(self.viewpoint), str):
            names.append("viewpoint")
        return names

    def _given_normals(self, clouds):
        """The normals given in the clouds' columns 3-5, packed as float32,
        and the mask of the points that have them (NaN rows elsewhere);
        ``(None, None)`` when every cloud's normals are to be estimated."""
        given = [has_normal_columns(c, self.normals) for c in clouds]
        if not any(given):
            return None, None
        if all(given):
            n = np.vstack([c[:, 3:6] for c in clouds]).astype(np.float32)
            return n, np.ones(len(n), dtype=bool)
        blocks = [
            c[:, 3:6] if g else np.full((len(c), 3), np.nan)
            for c, g in zip(clouds, given)
        ]
        mask = np.repeat(np.asarray(given), [len(c) for c in clouds])
        return np.vstack(blocks).astype(np.float32), mask

    def _compute(self, clouds, n_threads, out=None):
        """Packed descriptors, the undefined-point mask and the cloud offsets
        of validated clouds, the kernels on ``n_threads`` threads; into
        ``out`` (zeroed rows, one per point) when given."""
        k = self.n_neighbors
        if k is None and self.radius is None:
            k = self._default_n_neighbors
        xyz, offsets, nb, order = pack_neighborhoods(
            clouds, n_neighbors=k, radius=self.radius, n_threads=n_threads,
            with_sqdist=False, return_order=True,
        )  # fmt: skip
        if not self._grid_order or not scattered(nb):
            order = None
        if order is not None:
            # the points renumbered in the search's grid order (by cell):
            # neighbours close in memory, whatever the clouds' own order
            nb = nb.renumbered(order, n_threads)
        # float32 as PCL, each cloud in its local frame (far from the origin:
        # relative to its minimum), the viewpoint moved into the same frame
        p, origins = local_frame(xyz, offsets)
        if order is not None:
            p = p[order]
        given, mask = self._given_normals(clouds)
        if order is not None and given is not None:
            given, mask = given[order], mask[order]
        if given is not None and mask.all():
            n = given
        else:
            nnb = nb
            if self.normal_n_neighbors is not None or self.normal_radius is not None:
                _, _, nnb = pack_neighborhoods(
                    clouds,
                    n_neighbors=self.normal_n_neighbors,
                    radius=self.normal_radius,
                    n_threads=n_threads,
                    with_sqdist=False,
                )
                if order is not None:
                    nnb = nnb.renumbered(order, n_threads)
            vp = local_viewpoints(
                check_viewpoint(self.viewpoint), xyz, offsets, origins
            )
            n = normals_f32(p, nnb, vp, n_threads, offsets)[0]
            del nnb
            if given is not None:  # "auto" on clouds with and without normals
                n[mask] = given[mask]
        del xyz, given, mask  # the descriptors work in float32
        undefined = ~np.isfinite(n).all(axis=1) | (nb.sizes < 2)
        if order is not None:
            undefined[order] = undefined.copy()
        # the search's temporaries are freed: return their pages to the system
        # before the kernels allocate their outputs (lower peak memory)
        release_free_memory()
        pairs = self._pair_stage(p, n, nb, offsets, n_threads, out)
        del n  # no later stage reads the normals: freed before its output
        out = self._final_stage(p, pairs, nb, n_threads, out, order)
        return out, undefined, offsets

    def _pair_stage(self, p, n, nb, offsets, n_threads, out=None):
        """The kernels that read the normals (the pair features)."""
        raise NotImplementedError

    def _final_stage(self, p, pairs, nb, n_threads, out=None, rows=None):
        """The kernels after the normals are freed; by default none. Point
        ``i``'s row of the output is ``rows[i]`` when given (the points in
        grid order, :attr:`_grid_order`)."""
        return pairs

    def undefined_mask(self, X):
        """Which points have an undefined descriptor.

        A descriptor is undefined where the point's normal is undefined
        (estimated: fewer than 3 neighbours, or a collinear neighbourhood;
        given: a row with a NaN) or the point has no neighbour but itself.
        What :meth:`transform` does with those points is set by
        ``undefined``.

        Parameters
        ----------
        X : sequence of ndarray of shape (n_points_i, 3+)
            The clouds.

        Returns
        -------
        masks : list of ndarray of bool of shape (n_points_i,)
            True for the points whose descriptor is undefined.
        """
        return map_batches(self._undefined_batch, self._validate(X), self.n_jobs)

    def _undefined_batch(self, clouds, n_threads):
        _, undefined, offsets = self._compute(clouds, n_threads)
        return [undefined[offsets[i] : offsets[i + 1]] for i in range(len(offsets) - 1)]

    def transform(self, X):
        """Compute the descriptor of every point of every cloud.

        Parameters
        ----------
        X : sequence of ndarray of shape (n_points_i, 3+)
            The clouds, xyz first; with ``normals="auto"`` (the default)
            columns 3-5 of a cloud with 6 or more columns are its normals.

        Returns
        -------
        descriptors : list of ndarray of shape (n_rows_i, n_features) or ndarray of shape (n_clouds, n_features)
            One float32 array per cloud, a row per point (fewer with
            ``undefined="drop"``); with ``pooling``, one row per cloud.
        """  # noqa: E501
        return super().transform(X)

    def _transform_batch(self, clouds, n_threads):
        """:meth:`transform` of validated clouds (one batch of them)."""
        if self.pooling is not None:
            return self._pooled_batch(clouds, n_threads)
        return self._rows(*self._compute(clouds, n_threads))

    def _pooled_batch(self, clouds, n_threads):
        """The pooled rows of a batch, computed a part of at most
        :data:`_POOLED_PART` points at a time (whole clouds) in one output
        buffer, zeroed between parts: no array of every point's
        descriptor, and its pages faulted in once, not for each point of
        the batch (the same rows as all at once: clouds never interact)."""
        parts, size = [], 0
        for c in clouds:
            if not parts or size + len(c) > _POOLED_PART:
                parts.append([])
                size = 0
            parts[-1].append(c)
            size += len(c)
        largest = max(sum(len(c) for c in part) for part in parts)
        buffer = unshared_zeros((largest, self._width()), np.float32)
        pooled = []
        for k, part in enumerate(parts):
            m = sum(len(c) for c in part)
            if k:
                buffer[:m] = 0.0
            rows = self._rows(*self._compute(part, n_threads, buffer[:m]))
            pooled.extend(_pool(block, self.pooling) for block in rows)
        return np.vstack(pooled)

    def _rows(self, out, undefined, offsets):
        """The per-point rows of each cloud, undefined points as asked."""
        if self.undefined == "nan":
            out[undefined] = np.nan
        elif self.undefined == "zero":
            out[undefined] = 0.0
        rows = []
        for i in range(len(offsets) - 1):
            block = out[offsets[i] : offsets[i + 1]]
            if self.undefined == "drop":
                block = block[~undefined[offsets[i] : offsets[i + 1]]]
            rows.append(block)
        return rows

    def _feature_names(self):
        # pfh0, pfh1... or fpfh0, fpfh1...
        prefix = type(self).__name__.removesuffix("Transformer").lower()
        return numbered(prefix, self._width())

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.allow_nan = True
        return tags


def _pool(block, how):
    valid = block[np.isfinite(block).all(axis=1)]
    if len(valid) == 0:
        return np.full(block.shape[1], np.nan, dtype=np.float32)
    if how == "mean":
        return valid.mean(axis=0, dtype=np.float64).astype(np.float32)
    if how == "sum":
        return valid.sum(axis=0, dtype=np.float64).astype(np.float32)
    return valid.max(axis=0)
