"""Tiled scene segmentation: the answer of the untiled one, tile by tile.

:func:`segment_tiled` is the tiled :func:`~skpcd.segmentation.segment_scene`:
the scan is cut into buffered tiles (:mod:`skpcd.segmentation.tiling._spill`,
:mod:`skpcd.segmentation.tiling._geometry`), and three passes (ground, eps,
clusters) are mapped over them (:mod:`skpcd.segmentation.tiling._dispatch`);
see its docstring for why the tiled answer is the untiled one.
"""

import math
import shutil
import tempfile
from pathlib import Path

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from skpcd.io._common import check_chunk_size
from skpcd.segmentation._clusters import EUCLIDEAN_EPS, grid_dbscan
from skpcd.segmentation._structures import segment_structures
from skpcd.segmentation.tiling._dispatch import map_tiles
from skpcd.segmentation.tiling._eps import estimate_tiled_eps
from skpcd.segmentation.tiling._ground import (
    bases_tiled,
    csf_tiled,
    fill_given,
    ground_prepare,
    ground_reach,
    ground_tile,
    windowed_filter,
)
from skpcd.segmentation.tiling._spill import (
    detach,
    result_array,
    tile_scene,
)
from skpcd.utils._memory import release_free_memory

__all__ = ["default_buffer", "segment_tiled"]


def default_buffer(tile_size, ground, eps, structures):
    """The smallest tile buffer that keeps the tiled result the in-memory
    one (see ``tile_buffer`` in :func:`~skpcd.segmentation.segment_scene`)."""
    windowed = windowed_filter(ground)
    need = [0.0]
    if windowed is not None:
        need.append(ground_reach(windowed) + 2 * float(windowed.cell))
    if eps is not None:
        need.append(2 * eps)
        if structures is not None:
            need.append(structures_reach(eps))
    elif structures is not None:
        need.append(_STRUCTURES_REACH)  # checked once eps is estimated
    elif windowed is None:
        need.append(0.25 * tile_size)
    return 1.01 * max(need) + 1e-6


def _stitch(tiled, labels, chunk_size, size_range, exact, folder):
    """Join the segments of the tiles and number them as untiled.

    ``tiled`` yields ``((index, owned), (own_labels, shared, shared_labels,
    kinds))`` per tile: the scan indices of the tile's points and which it
    owns, the tile's labels of its own points, the positions (among its
    points) of the points it shares with the tiles that own them and its
    labels of those, and the kind of each of its segments (None: objects).
    Owned points get their tile's labels in ``labels``; two segments with a
    shared point are one. With ``exact`` (DBSCAN), every shared point is
    labelled by its owner too (the buffer rule); otherwise a shared point
    its owner leaves out links nothing. Segments outside ``size_range``
    are dropped; the others are numbered in the order of their first
    point. Returns the kind of each segment: that of the tile's segment
    holding most of its points.

    The shared points of all tiles (a share of the scan that grows with
    it) go to a file in ``folder`` as the tiles come, and are read back in
    chunks of ``chunk_size`` as the pairs of segments they link (see
    :func:`_link_pairs`); memory holds one tile's and the pairs."""
    n = len(labels)
    n_local, local_kinds, local_owned, tile_sizes = 0, [], [], []
    path = Path(folder) / "links.bin"
    n_links = 0
    with open(path, "wb") as f:
        for (index, owned), (own_labels, shared, shared_labels, kinds) in tiled:
            labels[index[owned]] = np.where(own_labels >= 0, own_labels + n_local, -1)
            np.column_stack([index[shared], shared_labels + n_local]).astype(
                np.int64, copy=False
            ).tofile(f)
            n_links += len(shared)
            n_top = max(
                int(own_labels.max(initial=-1)), int(shared_labels.max(initial=-1))
            )
            if kinds is not None:
                n_top = max(n_top, len(kinds) - 1)
            local_kinds.append(
                np.zeros(n_top + 1, np.int8) if kinds is None else kinds[: n_top + 1]
            )
            local_owned.append(
                np.bincount(own_labels[own_labels >= 0], minlength=n_top + 1)
            )
            n_local += n_top + 1
            tile_sizes.append(n_top + 1)
    # union of the segments through their shared points
    links = np.zeros((0, 2), np.int64)
    if n_links:
        links = np.memmap(path, dtype=np.int64, mode="r", shape=(n_links, 2))
    pairs, count = _link_pairs(links, labels, n_local, chunk_size, exact)
    del links
    path.unlink()
    if not exact and len(pairs):
        pairs = _mutual(pairs, count, np.cumsum(tile_sizes))
    graph = coo_matrix(
        (np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n_local, n_local)
    )
    _, component = connected_components(graph, directed=False)
    # sizes and first point of each segment, then the size range and the
    # numbering of the untiled run (order of the first point)
    n_comp = int(component.max(initial=-1)) + 1
    sizes = np.zeros(n_comp, dtype=np.int64)
    first = np.full(n_comp, n, dtype=np.int64)
    for start in range(0, n, chunk_size):
        part = labels[start : start + chunk_size]
        comp = component[part[part >= 0]]
        sizes += np.bincount(comp, minlength=n_comp)
        pos = np.flatnonzero(part >= 0) + start
        np.minimum.at(first, comp, pos)
    min_size, max_size = size_range
    keep = sizes >= min_size
    if max_size is not None:
        keep &= sizes <= max_size
    number = np.full(n_comp, -1, dtype=np.int64)
    kept = np.flatnonzero(keep)
    number[kept[np.argsort(first[kept], kind="stable")]] = np.arange(len(kept))
    final = np.append(number[component], -1)  # index -1: no cluster
    for start in range(0, n, chunk_size):
        part = labels[start : start + chunk_size]
        part[:] = final[part]
    # the kind of each segment: its largest part's (owned points)
    local_kinds = np.concatenate(local_kinds) if local_kinds else np.zeros(0, np.int8)
    owned = np.concatenate(local_owned) if local_owned else np.zeros(0, np.int64)
    order = np.lexsort((-owned, component))
    head = order[np.r_[True, component[order][1:] != component[order][:-1]]]
    comp_kind = np.zeros(n_comp, dtype=np.int8)
    comp_kind[component[head]] = local_kinds[head]
    return comp_kind[kept[np.argsort(first[kept], kind="stable")]]


def _link_pairs(links, labels, n_local, chunk_size, exact):
    """The distinct pairs ``(segment, owner's segment)`` that the shared
    points link, and how many shared points link each pair.

    ``links`` holds one row ``(point, segment)`` per shared point: its scan
    index and its segment in the tile that shares it; the owner's segment
    is ``labels[point]``; both segments are below ``n_local``. Rows whose
    owner leaves the point out are dropped (with ``exact``, the buffer rule
    forbids them: a RuntimeError). Read in chunks of ``chunk_size`` rows
    (``links`` may be a memory map), each chunk reduced to its distinct
    pairs, each pair one int64 key ``segment * n_local + owner's segment``
    (``n_local`` below 3 billion), so memory holds the pairs, not the rows.
    Returns ``(pairs, count)``, the pairs sorted as ``np.unique(rows,
    axis=0)`` sorts them."""
    keys, counts = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
    held = 0
    for start in range(0, len(links), chunk_size):
        rows = np.asarray(links[start : start + chunk_size])
        other = np.asarray(labels[rows[:, 0]])
        if exact and np.any(other < 0):  # pragma: no cover - the buffer rule
            raise RuntimeError("a shared core point is not core in its own tile")
        keep = other >= 0
        key, count = np.unique(
            rows[keep, 1] * n_local + other[keep], return_counts=True
        )
        keys.append(key)
        counts.append(count)
        held += len(key)
        if held > chunk_size:
            keys, counts = _merge_keys(keys, counts)
            held = len(keys[0])
    (key,), (count,) = _merge_keys(keys, counts)
    return np.column_stack([key // max(n_local, 1), key % max(n_local, 1)]), count


def _merge_keys(keys, counts):
    """The distinct keys of ``keys`` (a list of arrays) with their
    ``counts`` summed, as one-element lists."""
    key, inverse = np.unique(np.concatenate(keys), return_inverse=True)
    count = np.bincount(inverse, weights=np.concatenate(counts), minlength=len(key))
    return [key], [count.astype(np.int64)]


def _mutual(pairs, count, tile_ends):
    """The pairs ``(segment, owner's segment)`` that the shared points link
    (distinct, sorted, with ``count`` the shared points of each; see
    :func:`_link_pairs`) kept where the two segments hold the most of each
    other's shared points in that tile: a segment one tile sees whole and
    another tile splits (or the other way round) is joined to one part,
    not used to join the parts. Returns the kept pairs."""
    tile = np.searchsorted(tile_ends, pairs[:, 0], side="right")
    # for each of mine, the owner segment holding most of its shared points
    order = np.lexsort((-count, pairs[:, 0]))
    best_mine = order[np.r_[True, pairs[order, 0][1:] != pairs[order, 0][:-1]]]
    # for each owner segment in each tile, the tile's segment holding most
    key = np.column_stack([tile, pairs[:, 1]])
    order = np.lexsort((-count, key[:, 1], key[:, 0]))
    k = key[order]
    best_theirs = order[np.r_[True, np.any(k[1:] != k[:-1], axis=1)]]
    keep = np.intersect1d(best_mine, best_theirs)
    return pairs[keep]


# The structures step on tiles: each tile segments its points within
# structures_reach(eps) of its core square (facades and wires are found
# from pieces at least 4 m long, trunks from 1.2 m columns), and links its
# segments to those of the owners of its points within structures_link(eps)
# of its core square, where its view is nearly whole.
_STRUCTURES_REACH = 10.0


def structures_reach(eps):
    """Around each tile, the points the structures step sees (metres)."""
    return max(_STRUCTURES_REACH, 8 * eps)


def structures_link(eps):
    """Around each tile, the shared points that link its segments."""
    return structures_reach(eps) / 2


def _structures_prepare(xyz, index, ground, tile, grid, reach, link):
    """All the points of a buffered tile within ``reach`` of its core
    square, their ground flags, which it owns and which lie within
    ``link`` of its core square."""
    owned = grid.owner(xyz) == tile
    x0, y0, x1, y1 = grid.core_bounds(tile)
    x, y = xyz[:, 0], xyz[:, 1]

    def within(d):
        return (x >= x0 - d) & (x <= x1 + d) & (y >= y0 - d) & (y <= y1 + d)

    sel = within(reach) | owned
    args = (np.ascontiguousarray(xyz[sel]), ground[sel], owned[sel], within(link)[sel])
    return args, (index[sel], owned[sel])


def _structures_tile(xyz, ground, owned, near, eps, min_samples, params, n_threads):
    """The structures step (facades, wires, objects split at trunks) on a
    tile's points: labels of its own points, the positions and labels of
    the labelled points it shares near its core square, and the kind of
    each of its segments."""
    rest = np.flatnonzero(~ground)
    labels = np.full(len(xyz), -1, dtype=np.int64)
    kinds = np.zeros(0, dtype=np.int8)
    if len(rest) >= 2:
        pts = np.ascontiguousarray(xyz[rest])

        def cluster(mask):
            if mask.sum() < 2:
                return np.full(int(mask.sum()), -1, dtype=np.int64)
            sub = np.ascontiguousarray(pts[mask])
            return grid_dbscan(sub, eps, min_samples, n_jobs=n_threads)[0]

        sub, kinds, _ = segment_structures(
            pts, xyz[ground], eps, params, cluster, n_jobs=n_threads
        )
        labels[rest] = sub
    shared = np.flatnonzero(near & ~owned & (labels >= 0))
    return labels[owned], shared, labels[shared], kinds


def _cluster_prepare(xyz, index, ground, tile, grid, reach):
    """The non-ground points of a buffered tile within ``reach`` of its core
    square (and its own points); their scan indices and which are its own."""
    owned = grid.owner(xyz) == tile
    x0, y0, x1, y1 = grid.core_bounds(tile)
    x, y = xyz[:, 0], xyz[:, 1]
    sel = (
        (x >= x0 - reach) & (x <= x1 + reach)
        & (y >= y0 - reach) & (y <= y1 + reach)
    )  # fmt: skip
    sel |= owned
    sel &= ~ground
    return (np.ascontiguousarray(xyz[sel]), owned[sel]), (index[sel], owned[sel])


def _cluster_tile(xyz, owned, eps, min_samples, n_threads):
    """DBSCAN of the non-ground points of a buffered tile: labels of the
    owned points, and the positions and labels of the other core points."""
    labels, core = grid_dbscan(xyz, eps, min_samples, n_jobs=n_threads)
    shared = np.flatnonzero(core & ~owned)
    return labels[owned], shared, labels[shared], None


def segment_tiled(
    source,
    *,
    tile_size,
    tile_buffer,
    ground,
    given_ground=None,
    structures=None,
    method,
    eps,
    min_samples,
    min_cluster_size,
    max_cluster_size,
    random_state,
    n_jobs,
    eps_scale,
    chunk_size=1_000_000,
    temp_folder=None,
    unit=1.0,
):
    """The tiled path of :func:`~skpcd.segmentation.segment_scene`.

    ``ground`` is a GroundFilter (the preset resolved) or None;
    ``given_ground``, instead of a filter, the ground flags of the scan's
    points in file order, as consecutive boolean chunks of any length (a
    classification read from the file, flags given); ``structures`` None
    or the parameters of the structures step (the defaults merged); the
    other arguments are those of ``segment_scene``, validated, their
    lengths in metres: the coordinates are read multiplied by ``unit``
    (a message gives lengths in the units of the coordinates). Returns
    ``(labels, ground, eps, kinds)``: the first two as memory-mapped arrays
    (file already unlinked on POSIX systems), the kind of each segment (an
    index of ``KINDS``).
    """
    chunk_size = check_chunk_size(chunk_size)
    if method == "euclidean":
        eps, min_samples = (EUCLIDEAN_EPS if eps is None else float(eps)), 1
    windowed = windowed_filter(ground)
    reach = 0.0 if windowed is None else ground_reach(windowed)
    margin = 0.0 if windowed is None else 2 * float(windowed.cell)
    if tile_buffer is None:
        buffer = default_buffer(tile_size, ground, eps, structures)
    else:
        buffer = float(tile_buffer)
    ground_buffer = max(0.0, min(reach, buffer - margin))
    if eps is not None and structures is not None and structures_reach(eps) > buffer:
        raise ValueError(
            f"tile_buffer={buffer / unit:g} is too small for the structures "
            f"step: it needs at least {structures_reach(eps) / unit:g} around "
            "each tile"
        )
    if eps is not None and 2 * eps > buffer:
        raise ValueError(
            f"tile_buffer={buffer / unit:g} is too small for eps={eps / unit:g}: "
            "the stitching of segments across tiles needs at least 2 * eps = "
            f"{2 * eps / unit:g}"
        )
    # the C heap keeps what was freed (a sample of the scan read to tell its
    # kind, the spill's chunks) unless told to give it back: the tiles'
    # memory then comes on top of the scan's
    release_free_memory()
    scene = tile_scene(
        source, tile_size, buffer=buffer, chunk_size=chunk_size,
        temp_folder=temp_folder, unit=unit,
    )  # fmt: skip
    release_free_memory()
    out = Path(tempfile.mkdtemp(prefix="skpcd_labels_", dir=temp_folder))
    try:
        grid, n = scene.grid, scene.n_points
        tiles = np.flatnonzero(scene.owned_counts())
        is_ground = result_array(out, "ground.npy", n, np.bool_, False)
        labels = result_array(out, "labels.npy", n, np.int64, -1)

        ground_flags = (is_ground, str(out / "ground.npy"))

        # 1. ground: CSF with the cloth of the whole scan; SMRF, each tile's
        # filter on the cells of its core square grown by the filter's
        # reach, cut from the raster of the whole scene
        if given_ground is not None:
            fill_given(is_ground, given_ground)
        elif ground is not None and ground.method == "csf":
            bounds = csf_tiled(scene, tiles, ground, is_ground, n_jobs)
            if ground.keep_bases:
                bases_tiled(
                    scene, tiles, bounds, ground_buffer, ground_flags, out, n_jobs,
                    chunk_size,
                )  # fmt: skip
        elif ground is not None:
            cell = float(ground.cell)
            lo = scene.mins[:2]
            nxy = (np.floor((scene.maxs[:2] - lo) / cell) + 1).astype(np.int64)
            for index, flags in map_tiles(
                scene, tiles, ground_prepare, (grid, lo, nxy, cell, ground_buffer),
                ground_tile, (ground,), n_jobs,
            ):  # fmt: skip
                is_ground[index] = flags

        # 2. eps, once for the whole scan (see estimate_tiled_eps)
        if eps is None:
            eps = estimate_tiled_eps(
                scene, tiles, ground_flags, min_samples, eps_scale,
                random_state, n_jobs, chunk_size,
            )  # fmt: skip
            least = 2 * eps if structures is None else structures_reach(eps)
            if least > buffer and tile_buffer is not None:
                room = buffer / 2 if structures is None else buffer / 8
                raise ValueError(
                    f"the estimated eps={eps / unit:.6g} needs a tile buffer of "
                    f"at least {least / unit:g}, more than tile_buffer="
                    f"{buffer / unit:g}; pass tile_buffer="
                    f"{math.ceil(least * 1.01 / unit)} or more, or "
                    f"eps={room / unit:.4g} or less"
                )
            if least > buffer:  # the default buffer: cut again with enough
                buffer = 1.01 * least + 1e-6
                scene.close()
                release_free_memory()
                scene = tile_scene(
                    source, tile_size, buffer=buffer, chunk_size=chunk_size,
                    temp_folder=temp_folder, unit=unit,
                )  # fmt: skip
                grid = scene.grid
                tiles = np.flatnonzero(scene.owned_counts())

        # 3. clusters: each tile's DBSCAN on its non-ground points within
        # 2 * eps of its core square (with structures: its segmentation of
        # all its points within STRUCTURES_REACH); owned points keep its
        # labels, points shared with another tile link the two tiles'
        # segments
        kinds = np.zeros(0, dtype=np.int8)
        if eps > 0:
            if structures is None:
                reach_c = 2 * eps * (1 + 1e-9) + 1e-9
                tiled = map_tiles(
                    scene, tiles, _cluster_prepare, (grid, reach_c), _cluster_tile,
                    (eps, min_samples), n_jobs, ground=ground_flags,
                )  # fmt: skip
            else:
                tiled = map_tiles(
                    scene, tiles, _structures_prepare,
                    (grid, structures_reach(eps), structures_link(eps)),
                    _structures_tile, (eps, min_samples, structures), n_jobs,
                    ground=ground_flags,
                )  # fmt: skip
            kinds = _stitch(
                tiled,
                labels,
                chunk_size,
                (min_cluster_size, max_cluster_size),
                exact=structures is None,
                folder=out,
            )
        result = (
            detach(labels, out / "labels.npy"),
            detach(is_ground, out / "ground.npy"),
            float(eps),
            kinds,
        )
    finally:
        scene.close()
        shutil.rmtree(out, ignore_errors=True)
    return result
