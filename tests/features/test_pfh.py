import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skpcd.datasets import make_point_clouds
from skpcd.features import FPFHTransformer, PFHTransformer, compute_fpfh, compute_pfh
from skpcd.features._pair_kernels import pair_features
from skpcd.preprocessing import compute_neighborhoods, estimate_normals

F = np.float32


def ref_pair(p1, n1, p2, n2):
    """Slow NumPy float32 version of PCL's computePairFeatures."""

    def dot(a, b):
        return (a[0] * b[0] + a[2] * b[2]) + a[1] * b[1]

    d = (p2 - p1).astype(F)
    f4 = F(np.sqrt(dot(d, d)))
    if f4 == 0:
        return (0.0, 0.0, 0.0)
    a1, a2 = dot(n1, d) / f4, dot(n2, d) / f4
    if np.arccos(abs(a1)) > np.arccos(abs(a2)):
        u, t, d, f3 = n2, n1, -d, -a2
    else:
        u, t, f3 = n1, n2, a1
    v = np.cross(d, u).astype(F)
    vn = F(np.sqrt(dot(v, v)))
    if vn == 0:
        return (0.0, 0.0, 0.0)
    v = v / vn
    w = np.cross(u, v).astype(F)
    return (float(np.arctan2(dot(w, t), dot(u, t))), float(dot(v, t)), float(f3))


def ref_bin(f, n, angle):
    if np.isnan(f):
        return 0
    x = np.floor(n * ((f + np.pi) / (2 * np.pi) if angle else (f + 1.0) * 0.5))
    return int(min(max(x, 0), n - 1))


def ref_pfh(points, normals, nb, n_bins=5):
    out = np.zeros((len(points), n_bins**3))
    for i in range(len(points)):
        idx = nb.indices[nb.indptr[i] : nb.indptr[i + 1]]
        m = len(idx)
        for a in range(m):
            for b in range(a):
                f1, f2, f3 = ref_pair(
                    points[idx[a]], normals[idx[a]], points[idx[b]], normals[idx[b]]
                )
                h = ref_bin(f1, n_bins, True) + n_bins * ref_bin(f2, n_bins, False)
                h += n_bins**2 * ref_bin(f3, n_bins, False)
                out[i, h] += 100.0 / (m * (m - 1) // 2)
    return out


def _cloud(seed=0, n=120):
    pts = make_point_clouds(1, n_points=n, noise=0.01, random_state=seed)[0]
    normals, _ = estimate_normals(pts, n_neighbors=10)
    return pts.astype(F), normals.astype(F)


def test_pair_features_hand_computed():
    o, z, x = np.zeros(3, F), np.array([0, 0, 1], F), np.array([1, 0, 0], F)
    assert pair_features(o, z, x, z) == (0.0, 0.0, 0.0, 1.0)
    y = np.array([0, 1, 0], F)
    # no swap (tie): u = z, v = d x u = (0, -1, 0), w = u x v = (1, 0, 0),
    # f2 = v . y = -1, f1 = atan2(w . y, u . y) = 0
    assert pair_features(o, z, x, y) == (0.0, -1.0, 0.0, 1.0)
    # n2 = x makes the smaller angle with d: swapped, then d is parallel to u
    assert pair_features(o, z, x, x) == (0.0, 0.0, 0.0, 0.0)
    # a target normal tilted about d: f2 = v . t = -sin(0.3), f1 = 0
    t = np.array([0, np.sin(0.3), np.cos(0.3)], F)
    f1, f2, f3, f4 = pair_features(o, z, x, t)
    assert f1 == 0 and f2 == pytest.approx(-np.sin(0.3), abs=1e-7)
    assert f3 == 0 and f4 == 1
    # duplicates and offsets parallel to the normal fail and give zeros
    assert pair_features(o, z, o, x) == (0.0, 0.0, 0.0, 0.0)
    assert pair_features(o, z, z, z) == (0.0, 0.0, 0.0, 0.0)


def test_pair_features_equal_numpy_reference():
    pts, normals = _cloud(1)
    rng = np.random.default_rng(0)
    for i, j in rng.integers(0, len(pts), size=(500, 2)):
        got = pair_features(pts[i], normals[i], pts[j], normals[j])[:3]
        np.testing.assert_allclose(
            got, ref_pair(pts[i], normals[i], pts[j], normals[j]), atol=2e-6
        )


def test_pfh_equals_reference_and_sums_to_100():
    pts, normals = _cloud(2, 80)
    nb = compute_neighborhoods(pts, n_neighbors=8)
    got = compute_pfh(pts, normals, neighborhoods=nb)
    ref = ref_pfh(pts, normals, nb)
    assert got.dtype == np.float32 and got.shape == (80, 125)
    # float32 numpy and libm may differ by an ulp on a few bin edges
    close = np.abs(got - ref).sum(axis=1) < 1e-3
    assert close.mean() > 0.97
    np.testing.assert_allclose(got.sum(axis=1), 100, rtol=1e-5)


def test_pfh_bin_layout_f1_fastest():
    # two points, same normal, offset along x: the pair bins at f = (0, 0, 0)
    pts = np.array([[0, 0, 0], [1, 0, 0]], F)
    normals = np.array([[0, 0, 1], [0, 0, 1]], F)
    h = compute_pfh(pts, normals, n_neighbors=2)
    assert np.flatnonzero(h[0]).tolist() == [62] and h[0, 62] == 100
    # n2 along x makes f1 = pi/2: bin 3 for f1, 2 for f2 and f3
    normals[1] = [1, 0, 0]
    h = compute_pfh(pts, normals, n_neighbors=2, n_bins=5)
    f1, f2, f3, _ = pair_features(pts[1], normals[1], pts[0], normals[0])
    expect = (
        ref_bin(f1, 5, True) + 5 * ref_bin(f2, 5, False) + 25 * ref_bin(f3, 5, False)
    )
    assert np.flatnonzero(h[0]).tolist() == [expect]


def test_nan_normals_go_to_bin_zero_and_lone_points_are_zero():
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [50, 50, 50]], F)
    normals = np.array([[np.nan] * 3, [0, 0, 1], [0, 0, 1], [0, 0, 1]], F)
    h = compute_pfh(pts, normals, radius=2.0)
    assert (h[3] == 0).all()
    assert h[0].sum() == pytest.approx(100)
    # the pairs with the NaN-normal point have f1 = f2 = NaN (bin 0) at least
    assert h[0, [0, 25, 50, 75, 100]].sum() > 0


def test_fpfh_conventions_follow_their_definitions():
    pts, normals = _cloud(3, 150)
    nb = compute_neighborhoods(pts, n_neighbors=10)
    from skpcd.features._fpfh import _spfh

    s = _spfh(pts, normals, nb, 11)
    pcl = compute_fpfh(pts, normals, neighborhoods=nb)
    o3d = compute_fpfh(pts, normals, neighborhoods=nb, convention="open3d")
    paper = compute_fpfh(pts, normals, neighborhoods=nb, convention="paper")
    blocks = pcl.reshape(-1, 3, 11).sum(axis=2)
    np.testing.assert_allclose(blocks, 100, rtol=1e-4)
    np.testing.assert_allclose(o3d, pcl + s, rtol=1e-6)
    np.testing.assert_allclose(o3d.reshape(-1, 3, 11).sum(axis=2), 200, rtol=1e-4)
    # PCL's weighting, recomputed in float64
    i = 17
    idx = nb.indices[nb.indptr[i] : nb.indptr[i + 1]]
    d2 = nb.sqdist[nb.indptr[i] : nb.indptr[i + 1]].astype(np.float64)
    keep = d2 > 0
    acc = (s[idx[keep]] / d2[keep, None]).sum(axis=0).reshape(3, 11)
    np.testing.assert_allclose(
        pcl[i], (100 * acc / acc.sum(axis=1, keepdims=True)).ravel(), rtol=1e-4
    )
    paper_ref = s[i] + (s[idx[keep]] / np.sqrt(d2[keep, None])).sum(axis=0) / keep.sum()
    np.testing.assert_allclose(paper[i], paper_ref, rtol=1e-5)
    # SPFH: each block sums to 100
    np.testing.assert_allclose(s.reshape(-1, 3, 11).sum(axis=2), 100, rtol=1e-5)


def test_transformer_undefined_policies_and_pooling():
    line = np.column_stack([np.zeros(12), np.zeros(12), np.arange(12.0)])
    plane = make_point_clouds(1, n_points=60, random_state=4)[0]
    X = [plane, np.vstack([plane + 50, line])]
    t = PFHTransformer(n_neighbors=6)
    mask = t.undefined_mask(X)
    assert mask[0].sum() == 0 and mask[1][60:].all() and mask[1][:60].sum() == 0
    nan_rows = t.fit_transform(X)
    assert np.isnan(nan_rows[1][60:]).all() and np.isfinite(nan_rows[1][:60]).all()
    zero_rows = t.set_params(undefined="zero").fit_transform(X)
    assert (zero_rows[1][60:] == 0).all()
    dropped = t.set_params(undefined="drop").fit_transform(X)
    assert [len(d) for d in dropped] == [60, 60]
    kept = t.set_params(undefined="keep").fit_transform(X)
    np.testing.assert_allclose(kept[1][60:].sum(axis=1), 100, rtol=1e-5)
    pooled = t.set_params(undefined="nan", pooling="mean").fit_transform(X)
    np.testing.assert_allclose(pooled[1], nan_rows[1][:60].mean(axis=0), rtol=1e-5)
    np.testing.assert_allclose(pooled[0], nan_rows[0].mean(axis=0), rtol=1e-5)


def test_transformer_reads_normals_from_columns():
    pts, normals = _cloud(5, 70)
    X = [np.hstack([pts, normals]).astype(np.float64)]
    a = PFHTransformer(n_neighbors=9, normals="columns").fit_transform(X)[0]
    b = compute_pfh(pts, normals, n_neighbors=9)
    np.testing.assert_array_equal(a, b)
    with pytest.raises(ValueError, match="columns 3-5"):
        PFHTransformer(normals="columns").fit_transform([pts])


def test_transformer_argument_errors():
    X = make_point_clouds(2, n_points=30, random_state=0)
    with pytest.raises(ValueError, match="not both"):
        PFHTransformer(n_neighbors=5, radius=1.0).fit(X)
    with pytest.raises(ValueError, match="Wrap a single cloud"):
        FPFHTransformer().fit_transform(X[0])
    bad = X[0].copy()
    bad[0, 2] = np.inf
    with pytest.raises(ValueError, match=r"X\[1\] has NaN or infinite"):
        FPFHTransformer().fit_transform([X[1], bad])
    with pytest.raises(ValueError, match=r"X\[0\] has 0 point"):
        PFHTransformer().fit_transform([np.zeros((0, 3))])


def _rigid(seed):
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q, rng.uniform(-100, 100, 3)


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_invariant_to_rigid_motion_and_point_order(seed):
    pts = make_point_clouds(1, n_points=150, noise=0.01, random_state=seed)[0]
    pts -= pts.mean(axis=0)
    normals, _ = estimate_normals(pts, n_neighbors=10, viewpoint=(0, 0, 1e3))
    rot, shift = _rigid(seed)
    order = np.random.default_rng(seed).permutation(len(pts))
    cloud = np.hstack([pts, normals])
    moved = np.hstack([pts @ rot.T + shift, normals @ rot.T])
    # Over 200 seeds, the share of rows within L1 10 of the unmoved cloud was at
    # least 0.94 (PFH) and 0.89 (FPFH, which spreads a flip to the neighbours), and
    # the per-bin mean moved by at most 0.58: smooth synthetic patches have many
    # nearly parallel normals, the worst case for the swap rule.
    for cls, share in ((PFHTransformer, 0.9), (FPFHTransformer, 0.85)):
        t = cls(n_neighbors=10, normals="columns")
        base = t.fit_transform([cloud])[0]
        # point order: identical rows
        shuffled = t.fit_transform([cloud[order]])[0][np.argsort(order)]
        np.testing.assert_array_equal(shuffled, base)
        # rigid motion: float32 rounding moves a few pairs across bin edges or
        # flips the swap of nearly parallel normals (2.2 of 100 per pair)
        moved_rows = t.fit_transform([moved])[0]
        l1 = np.abs(moved_rows - base).sum(axis=1)
        assert np.mean(l1 <= 10) >= share
        assert np.abs(moved_rows.mean(axis=0) - base.mean(axis=0)).max() < 1.0


def test_fast_theta_bin_equals_atan2f_bin():
    from numba import njit

    from skpcd.features._pair_kernels import _bin_angle, _bin_theta

    @njit
    def both(fy, fx, n_bins):
        fast = np.empty(len(fy), np.int64)
        exact = np.empty(len(fy), np.int64)
        for t in range(len(fy)):
            fast[t] = _bin_theta(fy[t], fx[t], n_bins)
            exact[t] = _bin_angle(np.float32(np.arctan2(fy[t], fx[t])), n_bins)
        return fast, exact

    rng = np.random.default_rng(0)
    ang = rng.uniform(-np.pi, np.pi, 200_000)
    # angles at and around every bin edge, signed zeros, NaN, inf
    edges = -np.pi + 2 * np.pi * np.arange(12) / 11
    near = (edges[:, None] + np.linspace(-1e-4, 1e-4, 2001)[None, :]).ravel()
    ang = np.concatenate([ang, near, edges])
    r = rng.uniform(0.1, 1, len(ang))
    fy = np.concatenate([r * np.sin(ang), [0.0, -0.0, 0.0, -0.0, np.nan, 1, np.inf]])
    fx = np.concatenate([r * np.cos(ang), [0.0, 0.0, -0.0, -0.0, 1, np.nan, 1]])
    fy, fx = fy.astype(np.float32), fx.astype(np.float32)
    for n_bins in (5, 11):
        fast, exact = both(fy, fx, n_bins)
        np.testing.assert_array_equal(fast, exact)
    # the polynomial's error bound that the margin relies on
    a = np.linspace(0, 1, 1_000_001)
    z = a * a
    poly = a * (
        0.9998660
        + z * (-0.3302995 + z * (0.1801410 + z * (-0.0851330 + z * 0.0208351)))
    )
    assert np.abs(poly - np.arctan(a)).max() < 2e-5


def test_simd_kernels_equal_the_scalar_pair_path():
    # pfh_rows/spfh_rows bin most pairs in SIMD lanes and send the doubtful
    # ones (swap ties, f1 near an edge, zero distances, NaN) through _pair:
    # the result must be the scalar path's, in both layouts (small
    # neighbourhoods side by side, large ones one point at a time)
    from numba import njit

    from skpcd.features._fpfh import _fpfh_from_counts, _spfh_counts
    from skpcd.features._pair_kernels import ROW_MIN, _exact_code
    from skpcd.features._pfh import _radius_of, _space_order
    from skpcd.features._pfh_kernels import pfh_rows_reuse

    @njit
    def scalar(p, n, indptr, indices, n_bins, pfh, spfh):
        for i in range(len(indptr) - 1):
            s, e = indptr[i], indptr[i + 1]
            m = e - s
            if m > 1:
                incr = np.float32(100.0) / np.float32(m * (m - 1) // 2)
            for a in range(s, e):
                ia = indices[a]
                for b in range(s, e):
                    ib = indices[b]
                    if b < a:
                        c = _exact_code(
                            p[ia, 0], p[ia, 1], p[ia, 2], n[ia, 0], n[ia, 1], n[ia, 2],
                            p[ib, 0], p[ib, 1], p[ib, 2], n[ib, 0], n[ib, 1], n[ib, 2],
                            n_bins,
                        )  # fmt: skip
                        pfh[i, c] += incr
                    if a == s and ib != i:
                        c = _exact_code(
                            p[i, 0], p[i, 1], p[i, 2], n[i, 0], n[i, 1], n[i, 2],
                            p[ib, 0], p[ib, 1], p[ib, 2], n[ib, 0], n[ib, 1], n[ib, 2],
                            n_bins,
                        )  # fmt: skip
                        spfh[i, c % n_bins] += 1
                        spfh[i, n_bins + (c // n_bins) % n_bins] += 1
                        spfh[i, 2 * n_bins + c // (n_bins * n_bins)] += 1

    rng = np.random.default_rng(7)
    plane = np.c_[rng.uniform(0, 2, (300, 2)), np.zeros(300)]
    sphere = rng.normal(size=(300, 3))
    sphere /= np.linalg.norm(sphere, axis=1, keepdims=True)
    # a line whose pairs all tie (|a1| == |a2|, different normals): their bins
    # depend on which point comes first in each neighbourhood
    line = np.c_[3 + 0.05 * np.arange(20), np.zeros((20, 2))]
    tied = np.tile([[0.6, 0, 0.8], [0.6, 0.8, 0]], (10, 1))
    pts = np.vstack([plane, sphere, plane[:40], line]).astype(F)  # 40 duplicates
    up = np.tile([0, 0, 1], (300, 1))
    normals = np.vstack([up, sphere, up[:40], tied]).astype(F)
    normals[5] = np.nan
    normals[7] = [0, 0, -1]  # antiparallel: |a1| == |a2| ties
    # k nearest of varying sizes, and radii with 24+ neighbours
    searches = [{"n_neighbors": 10}, {"n_neighbors": 3}, {"radius": 0.35}]
    for search in searches:
        nb = compute_neighborhoods(pts, **search)
        if "radius" in search:
            assert (nb.sizes >= ROW_MIN).mean() > 0.3 and (nb.sizes < ROW_MIN).any()
        for n_bins in (5, 11):
            got = compute_pfh(pts, normals, neighborhoods=nb, n_bins=n_bins)
            ref = np.zeros_like(got)
            counts = np.zeros((len(pts), 3 * n_bins), np.int64)
            scalar(pts, normals, nb.indptr, nb.indices, n_bins, ref, counts)
            np.testing.assert_array_equal(got, ref)
            # pair codes reused between neighbourhoods, in any visiting order
            orders = [np.arange(len(pts)), rng.permutation(len(pts))]
            orders.append(_space_order(pts, _radius_of(pts, nb)))
            for rows in orders:
                reused = np.zeros_like(got)
                args = (pts, normals, nb.indptr, nb.indices, n_bins, reused)
                pos = np.full(len(pts), -1, dtype=np.int32)
                sorted_nb = (np.empty((0, 3)), np.empty(0, np.int32))
                none = np.empty(0, np.int64)
                pfh_rows_reuse(0, len(pts), rows, none, pos, *sorted_nb, *args)
                assert (pos == -1).all()
                np.testing.assert_array_equal(reused, ref)
            got_counts, table = _spfh_counts(pts, normals, nb, n_bins, 1)
            np.testing.assert_array_equal(got_counts, counts)
            # 4-bit counts, two per byte, where no point has more than 15 pairs
            packed, _ = _spfh_counts(pts, normals, nb, n_bins, 1, pack=True)
            if nb.sizes.max() - 1 > 15:
                assert packed.shape == counts.shape
                continue
            assert packed.shape == (len(pts), (3 * n_bins + 1) // 2)
            unpacked = np.stack([packed & 15, packed >> 4], axis=2)
            unpacked = unpacked.reshape(len(pts), -1)[:, : 3 * n_bins]
            np.testing.assert_array_equal(unpacked, counts)
            for convention in ("pcl", "open3d", "paper"):
                args = (table, nb, n_bins, convention, 1)
                np.testing.assert_array_equal(
                    _fpfh_from_counts(pts, packed, *args),
                    _fpfh_from_counts(pts, got_counts, *args),
                )


@pytest.mark.parametrize(
    ("est", "names"),
    [
        (PFHTransformer(n_bins=3, pooling="mean"), ["pfh0", "pfh26"]),
        (FPFHTransformer(pooling="max"), ["fpfh0", "fpfh32"]),
    ],
)
def test_feature_names_match_the_pooled_columns(est, names):
    X = make_point_clouds(3, n_points=(30, 40), random_state=0)
    out = est.fit_transform(X)
    got = est.get_feature_names_out()
    assert len(got) == out.shape[1]
    assert [got[0], got[-1]] == names


@pytest.mark.parametrize("normals", ["estimate", "columns", "auto"])
def test_radius_pfh_in_blocks_equals_one_pass(monkeypatch, normals):
    # the radius PFHTransformer searches and bins block by block (memory);
    # every row must be the one-pass result, whatever the blocks
    import skpcd.features._pfh as mod
    from skpcd.features._local_descriptor import _LocalDescriptor

    rng = np.random.default_rng(3)
    clouds = []
    for n in (700, 5, 1, 900):  # a tiny cloud: undefined normals and rows
        c = rng.uniform(0, 3, (n, 3))
        c[:, 2] *= 0.05
        n_c = rng.normal(size=(n, 3))  # given normals must be unit vectors
        clouds.append(np.c_[c, n_c / np.linalg.norm(n_c, axis=1, keepdims=True)])
    clouds[3][:30, :3] = clouds[3][30:60, :3]  # duplicates
    # pairs whose bins depend on which point comes first (|a1| == |a2|)
    line = np.c_[0.01 * np.arange(60), np.zeros((60, 2))]
    clouds.append(np.c_[line, np.tile([[0.6, 0, 0.8], [0.6, 0.8, 0]], (30, 1))])
    monkeypatch.setattr(mod, "_BLOCK", 97)
    for undefined in ("keep", "nan", "drop"):
        est = PFHTransformer(radius=0.45, normals=normals, undefined=undefined)
        got = est.fit_transform(clouds)
        with monkeypatch.context() as m:  # one search, one kernel call
            m.setattr(PFHTransformer, "_compute", _LocalDescriptor._compute)
            ref = est.fit_transform(clouds)
        assert len(got) == len(ref)
        for a, b in zip(got, ref, strict=True):
            np.testing.assert_array_equal(a, b)
    mask = est.undefined_mask(clouds)
    assert mask[2].all() and not mask[0].all()


@pytest.mark.parametrize(
    "est",
    [
        PFHTransformer(n_neighbors=8),
        PFHTransformer(radius=0.4),
        FPFHTransformer(n_neighbors=8),
        FPFHTransformer(n_neighbors=8, convention="paper"),
    ],
    ids=["pfh", "pfh-radius", "fpfh", "fpfh-paper"],
)
@pytest.mark.parametrize("pooling", ["mean", "sum", "max"])
def test_pooled_parts_give_the_pooled_rows_of_all_points(est, pooling, monkeypatch):
    from sklearn.base import clone

    from skpcd.features import _local_descriptor
    from skpcd.features._local_descriptor import _pool

    est = clone(est)
    X = make_point_clouds(9, n_points=300, random_state=3)
    X[4] = X[4][:2]  # undefined descriptors: NaN rows, left out of the pool
    rows = est.set_params(undefined="nan").fit_transform(X)
    expected = np.vstack([_pool(r, pooling) for r in rows])
    monkeypatch.setattr(_local_descriptor, "_POOLED_PART", 700)  # parts of 1-3 clouds
    pooled = est.set_params(pooling=pooling).fit_transform(X)
    np.testing.assert_array_equal(pooled, expected)
    whole = est.set_params(pooling=pooling).fit_transform([np.vstack(X)])
    monkeypatch.setattr(_local_descriptor, "_POOLED_PART", 10**9)  # one part
    np.testing.assert_array_equal(est.fit_transform(X), expected)
    np.testing.assert_array_equal(est.fit_transform([np.vstack(X)]), whole)


@pytest.mark.parametrize("convention", ["pcl", "open3d", "paper"])
def test_fpfh_of_a_shuffled_cloud_in_grid_order_is_the_same(convention, monkeypatch):
    # a shuffled cloud is computed renumbered in grid order (its neighbours
    # far apart in memory): the same bits as in its own order
    from skpcd.features._local_descriptor import _LocalDescriptor
    from skpcd.neighbors._neighbors import _NEAR, scattered, search_packed

    rng = np.random.default_rng(7)
    n = 4 * _NEAR
    s = np.sort(rng.random(n)) * 150.0
    xyz = np.column_stack([s, rng.random(n) * 3.0, np.sin(s) + rng.random(n) * 0.05])
    X = [xyz[rng.permutation(n)], xyz[:500]]
    ptr = np.array([0, n, n + 500])
    nb = search_packed(np.vstack(X), ptr, n_neighbors=10)
    assert scattered(nb)  # the renumbered path runs
    est = FPFHTransformer(n_neighbors=10, convention=convention, n_jobs=2)
    renumbered = est.transform(X)
    monkeypatch.setattr(FPFHTransformer, "_grid_order", _LocalDescriptor._grid_order)
    own = est.transform(X)
    for a, b in zip(renumbered, own):
        np.testing.assert_array_equal(a, b)
    pooled = est.set_params(pooling="mean").transform(X)
    monkeypatch.undo()
    np.testing.assert_array_equal(est.transform(X), pooled)
    # normals given with one cloud (columns 3-5), estimated for the other
    normals, _ = estimate_normals(X[0], n_neighbors=12)
    X6 = [np.hstack([X[0], normals]), X[1]]
    est.set_params(pooling=None)
    renumbered = est.transform(X6)
    monkeypatch.setattr(FPFHTransformer, "_grid_order", False)
    for a, b in zip(renumbered, est.transform(X6)):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(renumbered[0], own[0], equal_nan=True)


def test_fpfh_renumbered_keeps_undefined_points_radius_and_normal_search(monkeypatch):
    # the renumbered path with undefined points (a collinear group: no normal),
    # every undefined policy, undefined_mask, a radius search and a separate
    # normal search: the same rows as without renumbering
    from skpcd.neighbors._neighbors import _NEAR

    rng = np.random.default_rng(11)
    n = 4 * _NEAR
    s = np.sort(rng.random(n)) * 150.0
    strip = np.column_stack([s, rng.random(n) * 3.0, np.cos(s) + rng.random(n) * 0.05])
    line = np.column_stack(
        [np.linspace(0.0, 2.0, 40) + 400.0, np.zeros(40), np.zeros(40)]
    )
    X = [np.vstack([strip, line])[rng.permutation(n + 40)]]
    cases = [
        {"n_neighbors": 10, "undefined": "nan"},
        {"n_neighbors": 10, "undefined": "drop"},
        {"n_neighbors": 10, "undefined": "zero", "normal_n_neighbors": 15},
        {"radius": 0.2, "undefined": "nan"},
    ]
    for params in cases:
        est = FPFHTransformer(n_jobs=2, **params)
        renumbered, mask = est.transform(X), est.undefined_mask(X)
        monkeypatch.setattr(FPFHTransformer, "_grid_order", False)
        own, own_mask = est.transform(X), est.undefined_mask(X)
        monkeypatch.undo()
        np.testing.assert_array_equal(mask[0], own_mask[0])
        assert 40 <= mask[0].sum() < 200  # the line's points, undefined
        np.testing.assert_array_equal(renumbered[0], own[0])


def test_renumbered_refuses_what_is_not_a_permutation():
    nb = compute_neighborhoods(np.random.default_rng(0).random((50, 3)), n_neighbors=4)
    with pytest.raises(ValueError, match="permutation of the 50 points"):
        nb.renumbered(np.arange(49))
    with pytest.raises(ValueError, match="permutation"):
        nb.renumbered(np.r_[np.arange(49), 50])
    with pytest.raises(ValueError, match="repeats"):
        nb.renumbered(np.r_[np.arange(49), 0])
    with pytest.raises(ValueError, match="permutation"):
        nb.renumbered(np.arange(50.0))
    same = nb.renumbered(np.arange(50))
    np.testing.assert_array_equal(same.indices, nb.indices)
