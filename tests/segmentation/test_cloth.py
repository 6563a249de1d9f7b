"""The streamed cloth: CSF's flags of a scene seen in chunks, bit for bit."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skpcd.io import read_point_cloud
from skpcd.segmentation.ground._cloth import StreamedCloth
from skpcd.segmentation.ground._csf import csf_ground
from skpcd.segmentation.ground._presets import GROUND_PRESETS
from skpcd.utils._geometry import point_bounds

PARAMS = {
    "cloth_resolution": GROUND_PRESETS["csf"]["cell"],
    "class_threshold": GROUND_PRESETS["csf"]["threshold"],
    "rigidness": GROUND_PRESETS["csf"]["rigidness"],
    "slope_smooth": GROUND_PRESETS["csf"]["slope_smooth"],
    "iterations": 500,
    "time_step": 0.65,
}


def streamed_ground(xyz, parts):
    """CSF flags of ``xyz`` given to a StreamedCloth in ``parts`` (lists of
    point indices, in any order)."""
    lo, hi = point_bounds(xyz)
    cloth = StreamedCloth(PARAMS, lo, hi, len(xyz))
    if cloth.needs_cells:
        for p in parts:
            cloth.add_cells(xyz[p])
    for p in parts:
        cloth.sample(xyz[p], p)
    cloth.simulate()
    out = np.zeros(len(xyz), dtype=bool)
    for p in parts:
        out[p] = cloth.classify(xyz[p])
    return out, cloth.needs_cells


def shuffled_parts(n, n_parts, seed):
    order = np.random.default_rng(seed).permutation(n)
    return np.array_split(order, n_parts)


@pytest.mark.parametrize("which", [0, 4, 10])
def test_real_sweeps_bit_for_bit(real_sweeps, which):
    # KITTI (one group), PandaSet ego frame (one group), PandaSet world
    # frame (islands of occupied cells): the chunks in a random order
    xyz = read_point_cloud(real_sweeps[which])
    whole = csf_ground(xyz, **PARAMS)
    got, _ = streamed_ground(xyz, shuffled_parts(len(xyz), 7, which))
    assert 0.05 < whole.mean() < 0.95
    np.testing.assert_array_equal(got, whole)


def test_islands_and_a_lone_group(real_sweeps):
    # two sweeps 500 m apart (a cloth each) and five points far from both
    # (too few for a cloth: ground, as csf_ground says)
    a = read_point_cloud(real_sweeps[0])
    b = read_point_cloud(real_sweeps[4]) + np.array([500.0, 0.0, 3.0])
    far = np.random.default_rng(0).uniform([0, 900, 0], [5, 905, 1], (5, 3))
    xyz = np.vstack([a, b, far])
    whole = csf_ground(xyz, **PARAMS)
    got, islands = streamed_ground(xyz, shuffled_parts(len(xyz), 5, 1))
    assert islands
    assert whole[-5:].all()
    np.testing.assert_array_equal(got, whole)


@settings(max_examples=10, deadline=None)
@given(
    seed=st.integers(0, 2**16),
    n_parts=st.integers(1, 9),
    offset=st.sampled_from([0.0, 1234.5, 5.0e5]),
)
def test_any_chunks_any_place(seed, n_parts, offset):
    # a rough terrain with boxes on it; the answer does not depend on the
    # chunks, their order, or where the scene lies (shifted as CSF is)
    rng = np.random.default_rng(seed)
    ground = np.column_stack(
        [rng.uniform(0, 40, (6000, 2)), rng.normal(0.0, 0.03, 6000)]
    )
    boxes = rng.uniform([5, 5, 0.2], [12, 9, 2.5], (800, 3))
    xyz = np.vstack([ground, boxes]) + np.array([offset, -offset, offset / 10])
    whole = csf_ground(xyz, **PARAMS)
    got, _ = streamed_ground(xyz, shuffled_parts(len(xyz), n_parts, seed))
    np.testing.assert_array_equal(got, whole)
    assert whole[:6000].mean() > 0.9 and whole[6000:].mean() < 0.5
