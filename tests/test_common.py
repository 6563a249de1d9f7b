"""Common checks for every public estimator: sklearn's data-free ones and ours."""

import pytest
from sklearn.linear_model import LogisticRegression
from sklearn.utils import estimator_checks as sk

from skpcd.classification import TwoStepClassifier
from skpcd.datasets import make_point_clouds, make_urban_objects
from skpcd.features import (
    FPFHTransformer,
    ImprovedPFHTransformer,
    OverallDescriptor,
    PFHTransformer,
    ShapeFeatures,
)
from skpcd.preprocessing import GridSampler, NormalEstimator
from skpcd.utils.estimator_checks import ragged_checks

# Estimators taking a list of clouds as X; those taking 2-D X go through
# sklearn's parametrize_with_checks instead.
RAGGED = [
    ShapeFeatures(),
    NormalEstimator(n_neighbors=8),
    PFHTransformer(n_neighbors=8),
    FPFHTransformer(n_neighbors=8),
    PFHTransformer(radius=0.3, pooling="mean", undefined="drop"),
    FPFHTransformer(n_neighbors=8, convention="open3d", pooling="max"),
    ImprovedPFHTransformer(n_neighbors=8),
    ImprovedPFHTransformer("fpfh", middle="bbox_center", undefined="zero"),
    OverallDescriptor(),
    OverallDescriptor(box="obb_xy"),
    GridSampler(voxel_size=0.2),
    GridSampler(),
]

# sklearn checks that need no data and therefore apply to ragged estimators.
DATA_FREE_CHECKS = [
    sk.check_estimator_cloneable,
    sk.check_estimator_repr,
    sk.check_no_attributes_set_in_init,
    sk.check_parameters_default_constructible,
    sk.check_get_params_invariance,
    sk.check_set_params,
    sk.check_do_not_raise_errors_in_init_or_set_params,
    sk.check_mixin_order,
    sk.check_valid_tag_types,
    sk.check_estimator_tags_renamed,
    sk.check_param_validation,
]


# Meta-estimators: sklearn's data-free checks need an instance with its
# required sub-estimators (their 2-D checks run in their own test modules).
META = [TwoStepClassifier(LogisticRegression(), groups={"g": [1, 2]})]


def _id(obj):
    return getattr(obj, "__name__", type(obj).__name__)


@pytest.mark.parametrize("check", DATA_FREE_CHECKS, ids=_id)
@pytest.mark.parametrize("estimator", RAGGED + META, ids=_id)
def test_sklearn_data_free_checks(estimator, check):
    check(type(estimator).__name__, estimator)


@pytest.mark.parametrize("check", ragged_checks(), ids=_id)
@pytest.mark.parametrize("estimator", RAGGED, ids=_id)
def test_ragged_checks(estimator, check):
    X = make_point_clouds(6, n_points=(20, 60), random_state=0)
    check(estimator, X)


def test_ragged_checks_supervised_pipeline():
    from skpcd.classification import make_default_pipeline
    from skpcd.utils.estimator_checks import check_ragged_estimator

    clouds, labels = make_urban_objects(n_per_class=3, random_state=0)
    model = make_default_pipeline().set_params(randomforestclassifier__n_estimators=10)
    check_ragged_estimator(model, clouds, labels)
