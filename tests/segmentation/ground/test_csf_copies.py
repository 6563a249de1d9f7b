"""The CSF stage without its copies: the shifted points and the fill
written in place, the index lists read in one piece; the same ground flags
as the straightforward computation, on a real sweep."""

import CSF
import numpy as np

from skpcd.io import read_point_cloud
from skpcd.segmentation.ground import _csf
from skpcd.segmentation.ground._csf import _far_fill, _indices, csf_ground
from skpcd.utils._geometry import point_bounds

PARAMS = {
    "cloth_resolution": 1.0, "class_threshold": 0.3, "rigidness": 3,
    "slope_smooth": True, "iterations": 500, "time_step": 0.65,
}  # fmt: skip


def test_indices_equal_the_elementwise_read():
    values = [5, -3, 0, 2**31 - 1, -(2**31), 7, 7, 123456789]
    vec = CSF.VecInt(values)
    got = _indices(vec)
    assert got.dtype == np.int64
    np.testing.assert_array_equal(got, values)
    assert len(_indices(CSF.VecInt())) == 0


def test_far_fill_from_the_corner_equals_the_shifted_fill():
    rng = np.random.default_rng(3)
    # an L-shaped street far from the origin: empty cells to fill
    a = rng.uniform([0, 0, 0], [60, 8, 3], (6000, 3))
    b = rng.uniform([0, 0, 0], [8, 60, 3], (6000, 3))
    xyz = np.vstack([a, b]) + np.array([512345.678, 4876543.21, 101.5])
    corner = point_bounds(xyz)[0]
    expected = _far_fill(np.ascontiguousarray(xyz - corner), 1.0)
    got = _far_fill(xyz, 1.0, corner)
    assert len(expected) > 100
    np.testing.assert_array_equal(got, expected)


def _straightforward_once(xyz, **params):
    """The CSF run of one group as it was written first: a shifted copy,
    the fill stacked under it, every index read through the iterator."""
    shifted = np.ascontiguousarray(xyz - point_bounds(xyz)[0])
    fill = _far_fill(shifted, float(params["cloth_resolution"]))
    if len(fill):
        shifted = np.vstack([shifted, fill])
    csf = _csf._configured(params)
    on, off = CSF.VecInt(), CSF.VecInt()
    with _csf._reference_run():
        csf.setPointCloud(shifted)
        csf.do_filtering(on, off, False)
    idx = np.fromiter(on, dtype=np.int64, count=on.size())
    ground = np.zeros(len(xyz), dtype=bool)
    ground[idx[idx < len(xyz)]] = True
    return ground


def test_csf_ground_equals_the_straightforward_run(real_sweeps):
    xyz = read_point_cloud(real_sweeps[0])[:, :3]
    xyz = np.ascontiguousarray(xyz[: len(xyz) // 2])
    ground = csf_ground(xyz, **PARAMS)
    expected = _straightforward_once(xyz, **PARAMS)
    assert 0.1 < expected.mean() < 0.9
    np.testing.assert_array_equal(ground, expected)
