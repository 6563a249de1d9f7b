#!/usr/bin/env python3
"""Check the PCL fixtures in tests/data/pcl/ for internal consistency (numpy + stdlib only).

Usage:
    python benchmarks/pcl_reference/check_fixtures.py [--dir tests/data/pcl] [--libm | --no-libm] [NAME ...]

For every fixture it
  * checks the neighbour table: every point is its own neighbour at distance 0, distances are
    ascending and equal FLANN's float32 ((0 + dx*dx) + dy*dy) + dz*dz, and the set is a true
    k-NN / radius set against brute force (strict `d < r*r`, as FLANN);
  * checks the normals: unit length, flipped towards the viewpoint, parallel to a float64
    eigen-solution, NaN exactly where PCL 1.13's rules predict (< 3 neighbours, rank <= 1);
  * checks the histograms: PFH rows sum to 100 (zero when the point is its only neighbour),
    every FPFH block sums to 100 (or the row is all zero);
  * recomputes PFH-125 and FPFH-33 for every row from the fixture's points, normals and
    neighbour table with the rules in shared/reference/pcl-conventions.md, in float32, and
    reports how many rows are bit-identical.

Transcendentals: numpy's float32 arccos/arctan2 are not glibc's acosf/atan2f (numpy may use
SIMD versions). With --libm (the default) the script evaluates in float64 and calls glibc's
acosf/atan2f through ctypes only where the result can matter (the swap test when the two
arccos values are within a few float32 ulps, and f1 when it lies near a bin edge). --no-libm
uses numpy's float32 functions everywhere, as a plain numpy reimplementation would.
"""

from __future__ import annotations

import argparse
import ctypes
import ctypes.util
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
F32 = np.float32
PI = np.pi
D_PI = F32(1.0) / (F32(2.0) * F32(np.pi))  # float d_pi_ = 1.0f / (2.0f * (float) M_PI)


# ---------------------------------------------------------------------------------------
# float32 arithmetic in Eigen's SSE order (w = 0): dot = (x0*y0 + x2*y2) + (x1*y1 + 0)
# ---------------------------------------------------------------------------------------
def dot(a, b):
    return (a[..., 0] * b[..., 0] + a[..., 2] * b[..., 2]) + a[..., 1] * b[..., 1]


def cross(a, b):
    return np.stack(
        [
            a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
            a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
            a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
        ],
        axis=-1,
    )


class Trig:
    """acosf / atan2f as glibc computes them (libm=True) or as numpy float32 does."""

    def __init__(self, libm: bool):
        self.libm = libm
        self.calls = 0
        if libm:
            lib = ctypes.CDLL(ctypes.util.find_library("m") or "libm.so.6")
            self._acosf = lib.acosf
            self._acosf.restype, self._acosf.argtypes = ctypes.c_float, [ctypes.c_float]
            self._atan2f = lib.atan2f
            self._atan2f.restype, self._atan2f.argtypes = (
                ctypes.c_float,
                [ctypes.c_float, ctypes.c_float],
            )

    def acosf(self, x: np.ndarray) -> np.ndarray:
        self.calls += x.size
        return np.array([self._acosf(v) for v in x.tolist()], dtype=F32)

    def atan2f(self, y: np.ndarray, x: np.ndarray) -> np.ndarray:
        self.calls += y.size
        return np.array(
            [self._atan2f(a, b) for a, b in zip(y.tolist(), x.tolist())], dtype=F32
        )

    def swap(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """acos(x) > acos(y) for x, y = |a1|, |a2| (float32, NaN -> False)."""
        if not self.libm:
            return np.arccos(x) > np.arccos(y)
        with np.errstate(invalid="ignore"):
            ax, ay = np.arccos(x.astype(np.float64)), np.arccos(y.astype(np.float64))
            res = ax > ay
            # glibc's acosf is monotone and within 1 ulp: decide ties and near-ties by calling it
            close = np.abs(ax - ay) <= 4 * np.spacing(
                np.maximum(ax, ay).astype(F32)
            ).astype(np.float64)
        close &= (
            x != y
        )  # equal inputs -> equal outputs -> no swap (res is already False)
        if close.any():
            res[close] = self.acosf(x[close]) > self.acosf(y[close])
        return res

    def f1(self, y: np.ndarray, x: np.ndarray, nr: int) -> np.ndarray:
        """float atan2f(y, x); exact glibc value wherever the bin of f1 could depend on it."""
        if not self.libm:
            return np.arctan2(y, x)
        with np.errstate(invalid="ignore"):
            f = np.arctan2(y.astype(np.float64), x.astype(np.float64))
            pos = nr * ((f + PI) * np.float64(D_PI))
            near = np.abs(pos - np.round(pos)) < 1e-4
        out = f.astype(F32)
        if near.any():
            out[near] = self.atan2f(y[near], x[near])
        return out


def pair_features(P, N, i1, i2, trig: Trig):
    """pcl::computePairFeatures(p1=P[i1], n1=N[i1], p2=P[i2], n2=N[i2]).

    Returns ((w.n2, u.n2, failed), f2, f3) in float32; f1 = atan2f(w.n2, u.n2) is left to bins().
    """
    d = P[i2] - P[i1]
    n1, n2 = N[i1], N[i2]
    with np.errstate(invalid="ignore", divide="ignore"):
        f4 = np.sqrt(dot(d, d))
        a1 = dot(n1, d) / f4
        a2 = dot(n2, d) / f4
        sw = trig.swap(np.abs(a1), np.abs(a2))
        u = np.where(sw[:, None], n2, n1)
        t = np.where(sw[:, None], n1, n2)
        d = np.where(sw[:, None], -d, d)
        f3 = np.where(sw, -a2, a1)
        v = cross(d, u)
        vn = np.sqrt(dot(v, v))
        v = v / vn[:, None]
        w = cross(u, v)
        f2 = dot(v, t)
        wy, ux = dot(w, t), dot(u, t)  # f1 = atan2f(wy, ux), evaluated in bins()
    fail = (f4 == 0) | (
        vn == 0
    )  # PCL sets f1..f4 = 0 (and the wrapper bins them anyway)
    f2, f3 = (np.where(fail, F32(0), f).astype(F32) for f in (f2, f3))
    return (wy, ux, fail), f2, f3


def bins(f1_args, f2, f3, nr, trig: Trig):
    """PCL's binning in double; NaN -> bin 0 (x86 cvttsd2si gives INT_MIN, clamped to 0)."""
    wy, ux, fail = f1_args
    f1 = np.where(fail, F32(0), trig.f1(wy, ux, nr)).astype(F32)
    out = []
    with np.errstate(invalid="ignore"):
        for pos in (
            nr * ((f1.astype(np.float64) + PI) * np.float64(D_PI)),
            nr * ((f2.astype(np.float64) + 1.0) * 0.5),
            nr * ((f3.astype(np.float64) + 1.0) * 0.5),
        ):
            fl = np.floor(pos)
            idx = np.where(
                np.isnan(fl), 0, np.clip(np.nan_to_num(fl, nan=0.0), 0, nr - 1)
            ).astype(np.int64)
            out.append(idx)
    return out


def repeated_sum(incr: F32, counts: np.ndarray) -> np.ndarray:
    """Float32 value of `h += incr` done c times, for every c in counts."""
    cmax = int(counts.max()) if counts.size else 0
    table = np.zeros(cmax + 1, dtype=F32)
    acc = F32(0)
    for c in range(1, cmax + 1):
        acc = F32(acc + incr)
        table[c] = acc
    return table[counts]


# ---------------------------------------------------------------------------------------
# Fixture loading
# ---------------------------------------------------------------------------------------
def neighbour_lists(z) -> tuple[np.ndarray, np.ndarray]:
    """indptr (n+1,) and flat indices/sqdist, for k-NN and radius fixtures alike."""
    if "neighbors" in z:
        nb, sd = z["neighbors"], z["sqdist"]
        n, k = nb.shape
        return np.arange(n + 1, dtype=np.int64) * k, nb.ravel(), sd.ravel()
    return z["indptr"], z["indices"], z["sqdist"]


def recompute_pfh(P, N, indptr, ind, trig):
    n = len(P)
    out = np.zeros((n, 125), dtype=F32)
    # group rows by neighbourhood size so pairs can be generated in blocks
    sizes = np.diff(indptr)
    for m in np.unique(sizes):
        rows = np.nonzero(sizes == m)[0]
        if m < 2:
            continue  # only the point itself: all-zero histogram
        a, b = np.tril_indices(m, -1)  # i_idx > j_idx, i outer, j inner
        nb = ind[indptr[rows][:, None] + np.arange(m)[None, :]]  # (r, m)
        i1, i2 = nb[:, a].ravel(), nb[:, b].ravel()  # p1 = nb[i_idx], p2 = nb[j_idx]
        b1, b2, b3 = bins(*pair_features(P, N, i1, i2, trig), 5, trig)
        h = (b1 + 5 * b2 + 25 * b3).reshape(len(rows), -1)
        counts = np.zeros((len(rows), 125), dtype=np.int64)
        np.add.at(counts, (np.repeat(np.arange(len(rows)), h.shape[1]), h.ravel()), 1)
        incr = F32(100.0) / F32(m * (m - 1) // 2)
        out[rows] = repeated_sum(incr, counts)
    return out


def recompute_spfh(P, N, indptr, ind, trig):
    n = len(P)
    spfh = np.zeros((n, 33), dtype=F32)
    rows_all = np.repeat(np.arange(n), np.diff(indptr))
    keep = ind != rows_all  # q != p by index; duplicates at distance 0 stay
    p, q = rows_all[keep], ind[keep]
    b1, b2, b3 = bins(*pair_features(P, N, p, q, trig), 11, trig)
    counts = np.zeros((n, 33), dtype=np.int64)
    for off, bb in ((0, b1), (11, b2), (22, b3)):
        np.add.at(counts, (p, off + bb), 1)
    sizes = np.diff(indptr)
    for m in np.unique(sizes):
        if m < 2:
            continue
        rows = np.nonzero(sizes == m)[0]
        incr = F32(100.0) / F32(m - 1)
        spfh[rows] = repeated_sum(incr, counts[rows])
    return spfh


def recompute_fpfh(spfh, indptr, ind, sqd):
    n = len(indptr) - 1
    sizes = np.diff(indptr)
    width = int(sizes.max())
    acc = np.zeros((n, 33), dtype=F32)
    sums = np.zeros((n, 3), dtype=np.float64)
    for j in range(width):  # neighbour order as in the table
        has = sizes > j
        pos = indptr[:-1] + j
        pos = np.where(has, pos, 0)
        d = np.where(has, sqd[pos], F32(0))
        use = has & (d != 0)
        if not use.any():
            continue
        r = np.nonzero(use)[0]
        w = F32(1.0) / d[r]
        val = (spfh[ind[pos[r]]] * w[:, None]).astype(F32)
        for blk in range(3):
            for f in range(11):  # double sum in PCL's order: neighbour-major, bin-minor
                sums[r, blk] += val[:, blk * 11 + f].astype(np.float64)
        acc[r] = acc[r] + val
    out = np.empty_like(acc)
    for blk in range(3):
        s = sums[:, blk]
        with np.errstate(divide="ignore"):
            factor = np.where(s != 0, 100.0 / np.where(s != 0, s, 1.0), 0.0)
        out[:, blk * 11 : (blk + 1) * 11] = (
            acc[:, blk * 11 : (blk + 1) * 11].astype(np.float64) * factor[:, None]
        ).astype(F32)
    return out


# ---------------------------------------------------------------------------------------
# Checks
# ---------------------------------------------------------------------------------------
def check_table(z, P, indptr, ind, sqd, report):
    n = len(P)
    rows = np.repeat(np.arange(n), np.diff(indptr))
    self_in = np.zeros(n, dtype=bool)
    self_in[rows[ind == rows]] = True
    # with more than k exact duplicates the k-NN list can leave the point itself out
    last = sqd[indptr[1:] - 1] == 0  # whole row at distance 0
    report(
        "every point is its own neighbour (unless its row is all duplicates)",
        bool(np.all(self_in | last)),
    )
    report("self distance is 0", bool((sqd[ind == rows] == 0).all()))
    d = P[ind] - P[rows]
    flann = ((F32(0) + d[:, 0] * d[:, 0]) + d[:, 1] * d[:, 1]) + d[:, 2] * d[:, 2]
    report(
        "sqdist == FLANN float32 ((0+dx^2)+dy^2)+dz^2", bool(np.array_equal(flann, sqd))
    )
    asc = np.ones(n, dtype=bool)
    diffs = np.diff(sqd) < 0
    same_row = rows[1:] == rows[:-1]
    asc[rows[1:][diffs & same_row]] = False
    report("distances ascending in every row", asc.all())
    # brute force, float32, same formula
    D = np.empty((n, n), dtype=F32)
    for s in range(0, n, 512):
        dd = P[None, :, :] - P[s : s + 512, None, :]
        D[s : s + 512] = (
            (F32(0) + dd[..., 0] * dd[..., 0]) + dd[..., 1] * dd[..., 1]
        ) + dd[..., 2] * dd[..., 2]
    info = {"rows without the point itself (all-duplicate rows)": int((~self_in).sum())}
    if "k" in z:
        k = int(z["k"])
        srt = np.sort(D, axis=1)
        kth = srt[:, k - 1]
        ok = np.array_equal(np.sort(sqd.reshape(n, k), axis=1), srt[:, :k])
        report("k-NN distances equal brute force k smallest", ok)
        ties = int(((D <= kth[:, None]).sum(1) > k).sum())
        info["rows with a tie at the k-th distance (set depends on the tree)"] = ties
    else:
        r2 = F32(float(z["radius"]) ** 2)
        brute = [np.nonzero(D[i] < r2)[0] for i in range(n)]
        ok = all(
            np.array_equal(np.sort(ind[indptr[i] : indptr[i + 1]]), b)
            for i, b in enumerate(brute)
        )
        report("radius sets equal brute force d < float(r*r)", ok)
        info["points exactly at distance r (excluded)"] = int((D == r2).sum())
    return info, D


def check_normals(z, P, indptr, ind, report):
    Nn, curv = z["normals"], z["curvature"]
    vp = z["viewpoint"].astype(F32)
    n = len(P)
    fin = np.isfinite(Nn).all(1)
    sizes = np.diff(indptr)
    report(
        "finite normals have unit length",
        bool(np.all(np.abs(np.linalg.norm(Nn[fin], axis=1) - 1) < 1e-5)),
    )
    flip = dot(vp[None, :] - P, Nn)
    report(
        "normals face the viewpoint ((vp-p).n >= 0)", bool(np.all(flip[fin] >= -1e-4))
    )
    predicted_nan = np.zeros(n, dtype=bool)
    lam = np.zeros((n, 3))
    vec = np.zeros((n, 3))
    for i in range(n):
        nb = ind[indptr[i] : indptr[i + 1]]
        if len(nb) < 3:
            predicted_nan[i] = True
            continue
        Q = P[nb].astype(np.float64)
        C = np.cov(Q.T, bias=True)
        w, V = np.linalg.eigh(C)
        lam[i], vec[i] = w, V[:, 0]
        # rank <= 1: at most one non-zero eigenvalue (collinear or all duplicates)
        if w[1] <= 1e-12 * max(w[2], 1e-30):
            predicted_nan[i] = True
    report(
        "NaN normals exactly where predicted (<3 nb or rank<=1)",
        bool(np.array_equal(~fin, predicted_nan)),
    )
    few = sizes < 3
    report("<3 neighbours -> NaN curvature", bool(np.isnan(curv[few]).all()))
    ok = fin & ~predicted_nan
    cos = np.abs(np.sum(vec[ok] * Nn[ok], axis=1))
    tr = lam[ok].sum(1)
    c64 = np.where(tr > 0, np.abs(lam[ok, 0]) / np.where(tr > 0, tr, 1), 0)
    return {
        "NaN normals": int((~fin).sum()),
        "NaN curvature": int(np.isnan(curv).sum()),
        "min |cos| vs float64 eigh": float(cos.min()) if ok.any() else None,
        "max |curvature - float64|": float(np.abs(c64 - curv[ok]).max())
        if ok.any()
        else None,
    }


def check_fixture(path: Path, trig: Trig) -> bool:
    z = np.load(path)
    P, N = z["points"], z["normals"]
    indptr, ind, sqd = neighbour_lists(z)
    n = len(P)
    failures = []

    def report(what, ok):
        if not ok:
            failures.append(what)

    info, _ = check_table(z, P, indptr, ind, sqd, report)
    info.update(check_normals(z, P, indptr, ind, report))

    sizes = np.diff(indptr)
    pfh, fpfh = z["pfh"], z["fpfh"]
    s = pfh.sum(1, dtype=np.float64)
    # float32 accumulation of up to thousands of increments drifts by ~1e-3
    report(
        "PFH rows sum to 100 (0 when alone)",
        bool(np.all(np.where(sizes > 1, np.abs(s - 100) < 1e-2, s == 0))),
    )
    info["max |PFH row sum - 100|"] = float(np.abs(s[sizes > 1] - 100).max())
    blocks = fpfh.reshape(n, 3, 11).sum(2, dtype=np.float64)
    zero = (fpfh == 0).all(1)
    has_far = np.zeros(n, dtype=bool)
    has_far[np.repeat(np.arange(n), sizes)[sqd != 0]] = True
    report(
        "FPFH blocks sum to 100, zero rows exactly where no neighbour has d > 0",
        bool(np.all(np.abs(blocks[~zero] - 100) < 1e-2))
        and np.array_equal(zero, ~has_far),
    )
    info["FPFH all-zero rows"] = int(zero.sum())
    report("no NaN in PFH/FPFH", not (np.isnan(pfh).any() or np.isnan(fpfh).any()))

    calls0 = trig.calls
    pfh2 = recompute_pfh(P, N, indptr, ind, trig)
    spfh = recompute_spfh(P, N, indptr, ind, trig)
    fpfh2 = recompute_fpfh(spfh, indptr, ind, sqd)
    pfh_same = np.all(pfh2.view(np.uint32) == pfh.view(np.uint32), axis=1)
    fpfh_same = np.all(fpfh2.view(np.uint32) == fpfh.view(np.uint32), axis=1)
    fpfh_close = np.all(np.abs(fpfh2 - fpfh) <= 1e-3, axis=1)
    info["PFH rows bit-identical"] = f"{pfh_same.sum()}/{n}"
    info["FPFH rows bit-identical"] = f"{fpfh_same.sum()}/{n}"
    info["FPFH rows within 1e-3"] = f"{fpfh_close.sum()}/{n}"
    info["max |PFH diff|"] = float(np.abs(pfh2 - pfh).max())
    info["max |FPFH diff|"] = float(np.abs(fpfh2 - fpfh).max())
    if trig.libm:
        info["libm calls"] = trig.calls - calls0
        report("recomputed PFH bit-identical on every row", pfh_same.all())
        report("recomputed FPFH within 1e-3 on every row", fpfh_close.all())

    search = f"k={int(z['k'])}" if "k" in z else f"radius={float(z['radius']):g}"
    status = "OK  " if not failures else "FAIL"
    print(f"{status} {path.name} (n={n}, {search}, mean nb {sizes.mean():.2f})")
    for key, v in info.items():
        print(f"       {key}: {v}")
    for f in failures:
        print(f"       FAILED: {f}")
    return not failures


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--dir", type=Path, default=REPO / "tests" / "data" / "pcl")
    ap.add_argument("--libm", dest="libm", action="store_true", default=True)
    ap.add_argument("--no-libm", dest="libm", action="store_false")
    ap.add_argument("names", nargs="*")
    args = ap.parse_args()
    trig = Trig(args.libm)
    paths = sorted(args.dir.glob("*.npz"))
    if args.names:
        paths = [p for p in paths if p.stem in args.names]
    ok = all(check_fixture(p, trig) for p in paths)
    print("all fixtures consistent" if ok else "SOME CHECKS FAILED")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
