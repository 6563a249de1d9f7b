"""Per-point scores: the counts by hand, the chance figures of a shuffled
truth, invariance to the order of the points, and the errors."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skpcd.metrics import format_scan_scores, scan_scores


def test_counts_by_hand():
    truth = ["car"] * 4 + ["tree"] * 3 + ["ignore"] * 2 + ["kerb"]
    pred = ["car", "car", "tree", "pole", "tree", "tree", "car", "car", "car", "car"]
    s = scan_scores(truth, pred)
    assert s.classes == ["car", "kerb", "tree"]
    assert s.predicted == ["car", "kerb", "tree", "pole"]
    # car: TP 2, FN 2 (tree, pole), FP 2 (a tree point, the kerb point)
    assert s.iou["car"] == pytest.approx(2 / 6)
    assert s.precision["car"] == pytest.approx(2 / 4) and s.recall["car"] == 0.5
    assert s.iou["tree"] == pytest.approx(2 / 4) and s.iou["kerb"] == 0.0
    assert s.precision["kerb"] == 0.0
    assert s.miou == pytest.approx((2 / 6 + 0 + 2 / 4) / 3)
    assert s.accuracy == pytest.approx(4 / 8)
    assert s.n_points == 8 and s.n_ignored == 2
    np.testing.assert_array_equal(
        s.confusion, [[2, 0, 1, 1], [1, 0, 0, 0], [1, 0, 2, 0]]
    )
    np.testing.assert_allclose(s.confusion_normalized.sum(axis=1), 1.0)
    text = format_scan_scores(s)
    assert "mIoU      0.2778 over 3 classes" in text
    assert "accuracy  0.5000 on 8 points (2 ignored)" in text


def test_classes_given():
    truth = ["car", "car", "tree", "wall"]
    pred = ["car", "wall", "tree", "wall"]
    s = scan_scores(truth, pred, classes=["tree", "car"])
    assert s.classes == ["tree", "car"] and s.predicted[:2] == ["tree", "car"]
    assert s.iou == {"tree": 1.0, "car": 0.5}
    assert s.accuracy == 0.75  # the wall points count, unscored
    with pytest.raises(ValueError, match="class 'person' has no true point"):
        scan_scores(truth, pred, classes=["car", "person"])


def test_errors():
    with pytest.raises(ValueError, match="same length"):
        scan_scores(["a", "b"], ["a"])
    with pytest.raises(ValueError, match="no point left to score"):
        scan_scores(["ignore"], ["a"])


def test_perfect_prediction_scores_one():
    truth = np.repeat(["ground", "car", "tree"], [50, 20, 30])
    s = scan_scores(truth, truth)
    assert s.iou == {"car": 1.0, "ground": 1.0, "tree": 1.0} and s.accuracy == 1.0


def test_shuffled_truth_gives_chance_figures():
    """A prediction independent of the truth: per class ``IoU = p q / (p + q
    - p q)`` and accuracy ``sum p q``, with ``p`` and ``q`` the shares of the
    class in the truth and the prediction."""
    rng = np.random.default_rng(0)
    classes = np.array(["ground", "building", "car", "tree", "pole"])
    share = np.array([0.4, 0.25, 0.2, 0.1, 0.05])
    pred = rng.choice(classes, 400_000, p=share)
    truth = rng.permutation(pred)
    s = scan_scores(truth, pred)
    for c, p in zip(classes, share):
        assert s.iou[c] == pytest.approx(p * p / (2 * p - p * p), abs=0.005)
        assert s.recall[c] == pytest.approx(p, abs=0.005)
    assert s.accuracy == pytest.approx((share**2).sum(), abs=0.005)


@settings(max_examples=40, deadline=None)
@given(
    st.lists(st.tuples(st.sampled_from("abcd"), st.sampled_from("abcde")), min_size=1),
    st.randoms(use_true_random=False),
)
def test_order_of_points_does_not_matter(pairs, random):
    truth, pred = map(np.array, zip(*pairs))
    order = list(range(len(pairs)))
    random.shuffle(order)
    a, b = scan_scores(truth, pred), scan_scores(truth[order], pred[order])
    assert a.iou == b.iou and a.accuracy == b.accuracy
    np.testing.assert_array_equal(a.confusion, b.confusion)
    assert a.confusion.sum() == len(pairs)
