import contextlib
import hashlib
import importlib
import json
import os
import re
import subprocess
import sys
import textwrap

import joblib
import numpy as np
import pytest
from sklearn.base import BaseEstimator
from sklearn.dummy import DummyClassifier
from sklearn.ensemble import RandomForestClassifier
from sklearn.model_selection import GridSearchCV
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import FunctionTransformer

import skpcd
from skpcd.exceptions import (
    IncompatibleModelError,
    MissingFileError,
    PointCloudFileError,
    UntrustedModelError,
)
from skpcd.io import _model as m
from skpcd.io import _model_checks as checks
from skpcd.io import load_model, save_model


def _model():
    return DummyClassifier(strategy="most_frequent").fit([[0], [1], [2]], list("aab"))


def _split(data):
    """(header dict, payload bytes) of a model file's bytes."""
    (length,) = m._LENGTH.unpack(data[len(m._MAGIC) : m._PREFIX])
    header = json.loads(data[m._PREFIX : m._PREFIX + length])
    return header, data[m._PREFIX + length + m._DIGEST :]


def test_round_trip_keeps_model_versions_and_metadata(tmp_path):
    import sklearn
    import skops

    meta = {"data": "toy", "n": np.int64(3), "classes": {"a": 2}}
    path = save_model(_model(), tmp_path / "m.skpcd", metadata=meta)
    assert path.read_bytes().startswith(m._MAGIC)
    model, info = load_model(path, return_info=True)
    assert model.predict([[5]]).tolist() == ["a"]
    assert info["metadata"] == {"data": "toy", "n": 3, "classes": {"a": 2}}
    assert info["format"] == "skops"
    assert info["versions"]["skpcd"] == skpcd.__version__
    assert info["versions"]["scikit-learn"] == sklearn.__version__
    assert info["versions"]["skops"] == skops.__version__


def test_existing_file_is_kept_unless_overwrite(tmp_path):
    path = tmp_path / "m.skpcd"
    path.write_text("keep me")
    with pytest.raises(FileExistsError, match="overwrite=True"):
        save_model(_model(), path)
    assert path.read_text() == "keep me"
    save_model(_model(), path, overwrite=True)
    assert load_model(path).predict([[0]]).tolist() == ["a"]
    assert [p.name for p in tmp_path.iterdir()] == ["m.skpcd"]  # no temp file left


@pytest.mark.parametrize("format", ["skops", "joblib"])
@pytest.mark.parametrize("lib", ["skpcd", "scikit-learn"])
def test_model_from_another_release_is_refused(tmp_path, monkeypatch, lib, format):
    path = save_model(_model(), tmp_path / "m.skpcd", format=format)
    trust = format == "joblib"
    real = m._versions()
    other = dict(real, **{lib: "99.1.0"})
    monkeypatch.setattr(m, "_versions", lambda: other)
    with pytest.raises(IncompatibleModelError, match=rf"written with {lib} .*99\.1\.0"):
        load_model(path, trust_pickle=trust)
    # a patch release of the same major.minor is accepted
    patch = [*real[lib].split(".")[:2], "999"]
    monkeypatch.setattr(m, "_versions", lambda: dict(real, **{lib: ".".join(patch)}))
    assert load_model(path, trust_pickle=trust).predict([[0]]).tolist() == ["a"]
    monkeypatch.setattr(m, "_versions", lambda: other)
    assert load_model(path, check_versions=False, trust_pickle=trust) is not None


def test_not_a_model_file(tmp_path):
    with pytest.raises(MissingFileError):
        load_model(tmp_path / "none.skpcd")
    junk = tmp_path / "junk.skpcd"
    junk.write_bytes(b"\x00garbage")
    with pytest.raises(PointCloudFileError, match="not a model file"):
        load_model(junk)
    other = tmp_path / "other.joblib"
    joblib.dump(np.arange(3), other)
    with pytest.raises(UntrustedModelError, match="trust_pickle=True"):
        load_model(other)
    with pytest.raises(PointCloudFileError, match="not a model file written by skpcd"):
        load_model(other, trust_pickle=True)
    with pytest.raises(PointCloudFileError, match="signature is damaged"):
        damaged = tmp_path / "damaged.skpcd"
        data = bytearray(save_model(_model(), tmp_path / "ok.skpcd").read_bytes())
        data[3] ^= 0x20
        damaged.write_bytes(bytes(data))
        load_model(damaged)


def test_metadata_must_be_json(tmp_path):
    with pytest.raises(TypeError, match="JSON serialisable"):
        save_model(_model(), tmp_path / "m.skpcd", metadata={"bad": object()})
    assert not list(tmp_path.iterdir())
    with pytest.raises(ValueError, match="'skops' or 'joblib'"):
        save_model(_model(), tmp_path / "m.skpcd", format="pickle")


class _RunsCode:
    """Unpickling this calls ``os.mkdir(marker)``."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (os.mkdir, (self.marker,))


def _legacy(model, path, **dump):
    """A model file as skpcd wrote them before the container (format 1)."""
    payload = {
        "format": "skpcd-model",
        "format_version": 1,
        "versions": m._versions(),
        "metadata": {"data": "old"},
        "model": model,
    }
    joblib.dump(payload, path, **dump)
    return path


@pytest.mark.parametrize("kind", ["bare", "bare-compressed", "container"])
def test_malicious_pickle_is_never_run_without_trust_pickle(tmp_path, kind):
    # was: the pickle's __reduce__ ran (its file appeared) before the
    # content was refused
    marker = tmp_path / "pwned"
    path = tmp_path / "model.joblib"
    if kind == "container":
        save_model(_RunsCode(marker), path, format="joblib")
    else:
        _legacy(_RunsCode(marker), path, compress=3 if "compressed" in kind else 0)
    with pytest.raises(UntrustedModelError) as info:
        load_model(path)
    message = str(info.value)
    assert message.startswith(str(path))
    assert "trust_pickle=True" in message and "--trust-pickle" in message
    assert not marker.exists()
    # the flag is what runs it
    with contextlib.suppress(PointCloudFileError):
        load_model(path, trust_pickle=True)
    assert marker.exists()


def test_bare_joblib_model_loads_with_trust_pickle(tmp_path):
    path = _legacy(_model(), tmp_path / "old.joblib")
    model, info = load_model(path, trust_pickle=True, return_info=True)
    assert model.predict([[0]]).tolist() == ["a"]
    assert info["format"] == "joblib-bare"
    assert info["metadata"] == {"data": "old"}


@pytest.mark.parametrize(
    "field, value", [("versions", None), ("versions", {"skpcd": 1}), ("metadata", 3)]
)
def test_tampered_bare_joblib_is_a_clean_error(tmp_path, field, value):
    # was: AttributeError: 'NoneType' object has no attribute 'get'
    path = tmp_path / "old.joblib"
    _legacy(_model(), path)
    payload = joblib.load(path)
    payload[field] = value
    joblib.dump(payload, path)
    with pytest.raises(PointCloudFileError, match=rf"^{path}: corrupt .*{field}"):
        load_model(path, trust_pickle=True)


def test_joblib_format_needs_trust_pickle(tmp_path):
    path = save_model(_model(), tmp_path / "m.skpcd", format="joblib")
    with pytest.raises(UntrustedModelError, match=r"joblib pickle.*trust_pickle=True"):
        load_model(path)
    model, info = load_model(path, trust_pickle=True, return_info=True)
    assert model.predict([[0]]).tolist() == ["a"]
    assert info["format"] == "joblib"


def _tampered(tmp_path, change):
    """A model file whose header ``change(header)`` edited, checksummed anew."""
    data = save_model(_model(), tmp_path / "good.skpcd", overwrite=True).read_bytes()
    header, payload = _split(data)
    header = change(header) or header
    path = tmp_path / "bad.skpcd"
    path.write_bytes(m._pack(header, payload))
    return path


def _set(key, value, where=None):
    def change(header):
        (header[where] if where else header)[key] = value

    return change


@pytest.mark.parametrize(
    "change",
    [
        _set("versions", None),
        _set("versions", ["0.1"]),
        _set("skpcd", None, "versions"),
        _set("skpcd", 0.1, "versions"),
        _set("numpy", 2, "versions"),
        _set("metadata", None),
        _set("metadata", "toy"),
        _set("payload_size", "123"),
        _set("payload_size", -1),
        _set("payload_size", True),
        _set("payload_size", 10**30),
        _set("payload_sha256", None),
        _set("payload_sha256", "zz" * 32),
        _set("format_version", "2"),
        _set("format_version", 1),
        _set("format_version", None),
        _set("serializer", "pickle"),
        _set("serializer", None),
        _set("format", "other"),
        _set("estimator", 5),
        lambda header: [header],
        lambda header: "a string",
    ],
)
def test_tampered_header_is_a_clean_error(tmp_path, change):
    path = _tampered(tmp_path, change)
    with pytest.raises(PointCloudFileError, match=rf"^{path}: corrupt"):
        load_model(path)


def test_newer_format_and_unreadable_header(tmp_path):
    newer = _tampered(tmp_path, _set("format_version", 99))
    with pytest.raises(IncompatibleModelError, match="upgrade skpcd"):
        load_model(newer)
    for text in (b"{not json", b"\xff\xfe{}", b"[" * 100_000):
        head = m._MAGIC + m._LENGTH.pack(len(text)) + text
        path = tmp_path / "raw.skpcd"
        path.write_bytes(head + hashlib.sha256(head).digest())
        with pytest.raises(PointCloudFileError, match="corrupt model file header"):
            load_model(path)


def test_truncated_or_padded_files_are_clean_errors(tmp_path):
    data = save_model(_model(), tmp_path / "m.skpcd").read_bytes()
    path = tmp_path / "cut.skpcd"
    for n in [0, 5, 16, 20, 24, 60, len(data) - 33, len(data) - 1, len(data) + 1]:
        path.write_bytes(data[:n] if n <= len(data) else data + b"\0")
        with pytest.raises(PointCloudFileError, match=rf"^{path}: "):
            load_model(path)


class _Marker(BaseEstimator):
    """Building this from a file creates the file named by ``marker``."""

    def __init__(self, marker=None):
        self.marker = marker

    def __setstate__(self, state):
        open(state["marker"], "w").close()
        self.__dict__.update(state)


def test_untrusted_type_is_named_and_never_built(tmp_path):
    marker = tmp_path / "built"
    model = make_pipeline(FunctionTransformer(), _Marker(str(marker)))
    path = save_model(model, tmp_path / "m.skpcd")
    name = f"{_Marker.__module__}._Marker"
    expected = rf"does not trust: {re.escape(name)}"
    with pytest.raises(UntrustedModelError, match=expected) as info:
        load_model(path)
    assert info.value.types == [name]
    assert not marker.exists()
    # the caller may vouch for it
    assert load_model(path, trusted=[name]).steps[-1][1].marker == str(marker)
    assert marker.exists()
    # a function named by the file is a type skpcd does not trust either
    path = save_model(FunctionTransformer(func=os.system), tmp_path / "f.skpcd")
    with pytest.raises(UntrustedModelError, match=r"system") as info:
        load_model(path)
    assert info.value.types and all("system" in t for t in info.value.types)


def test_unserialisable_model_is_a_clear_error_and_leaves_no_file(tmp_path):
    with pytest.raises(TypeError, match="format='joblib'"):
        save_model({"gen": (i for i in range(3))}, tmp_path / "m.skpcd")
    assert not list(tmp_path.iterdir())


def test_trusted_types_are_classes_and_cover_skpcd_estimators():
    for name in m.TRUSTED_TYPES:
        module, _, cls = name.rpartition(".")
        assert isinstance(getattr(importlib.import_module(module), cls), type), name
    estimators = set()
    for sub in ("classification", "encoding", "features", "preprocessing"):
        mod = importlib.import_module(f"skpcd.{sub}")
        for attr in mod.__all__:
            obj = getattr(mod, attr)
            if isinstance(obj, type) and issubclass(obj, BaseEstimator):
                estimators.add(f"{obj.__module__}.{obj.__qualname__}")
    mod = importlib.import_module("skpcd.segmentation")
    for attr in mod.__all__:
        obj = getattr(mod, attr)
        if isinstance(obj, type) and issubclass(obj, BaseEstimator):
            estimators.add(f"{obj.__module__}.{obj.__qualname__}")
    assert len(estimators) >= 13
    assert estimators <= set(m.TRUSTED_TYPES)


def _skpcd_models():
    from skpcd.classification import (
        CaseBasedClassifier,
        TwoStepClassifier,
        make_named_pipeline,
    )
    from skpcd.encoding import BagOfFeatures
    from skpcd.features import (
        FPFHTransformer,
        ImprovedPFHTransformer,
        OverallDescriptor,
        PFHTransformer,
        ShapeFeatures,
    )
    from skpcd.preprocessing import GridSampler, NormalEstimator

    forest = RandomForestClassifier(n_estimators=5, random_state=0)
    return {
        "pfh": PFHTransformer(n_neighbors=10),
        "pfh-mean": PFHTransformer(n_neighbors=10, pooling="mean"),
        "fpfh": FPFHTransformer(n_neighbors=10, pooling="mean"),
        "improved-pfh": ImprovedPFHTransformer(),
        "shape": ShapeFeatures(),
        "overall": OverallDescriptor(),
        "normals": NormalEstimator(),
        "grid": GridSampler(),
        "bag": make_pipeline(
            FPFHTransformer(n_neighbors=10),
            BagOfFeatures(n_words=6, random_state=0),
            RandomForestClassifier(n_estimators=5, random_state=0),
        ),
        "case-based-classifier": make_pipeline(
            ImprovedPFHTransformer(), CaseBasedClassifier(threshold=0.5)
        ),
        "two-step": make_pipeline(
            ShapeFeatures(),
            TwoStepClassifier(forest, groups={"small": ["car", "pole"]}),
        ),
        "grid-search": GridSearchCV(
            make_pipeline(ShapeFeatures(), forest),
            {"randomforestclassifier__max_depth": [2, None]},
            cv=2,
        ),
        "default": make_named_pipeline("default"),
        "case-based": make_named_pipeline("case-based"),
    }


def _outputs(model, clouds):
    if hasattr(model, "predict"):
        out = [model.predict(clouds)]
        if hasattr(model, "predict_proba"):
            out.append(model.predict_proba(clouds))
        return out
    out = model.transform(clouds)
    return list(out) if isinstance(out, list) else [out]


@pytest.fixture(scope="module")
def urban():
    from skpcd.datasets import make_urban_objects

    clouds, labels = make_urban_objects(n_per_class=4, random_state=0)
    return clouds, np.asarray(labels)


@pytest.mark.parametrize("name", list(_skpcd_models()))
def test_skpcd_estimators_round_trip_through_skops(tmp_path, urban, name):
    clouds, labels = urban
    model = _skpcd_models()[name].fit(clouds, labels)
    path = save_model(model, tmp_path / "m.skpcd")
    back = load_model(path)
    assert type(back) is type(model)
    for a, b in zip(_outputs(model, clouds), _outputs(back, clouds), strict=True):
        np.testing.assert_array_equal(a, b)


def test_skpcd_scene_estimators_round_trip_through_skops(tmp_path, urban):
    from skpcd.segmentation import AutoEpsDBSCAN, EuclideanClusters, GroundFilter

    scene = np.vstack(urban[0][:8])
    ground = GroundFilter().fit(scene)
    back = load_model(save_model(ground, tmp_path / "g.skpcd"))
    np.testing.assert_array_equal(back.predict(scene), ground.predict(scene))
    for est in (AutoEpsDBSCAN(random_state=0), EuclideanClusters(min_cluster_size=5)):
        est.fit(scene)
        back = load_model(save_model(est, tmp_path / f"{type(est).__name__}.skpcd"))
        np.testing.assert_array_equal(back.labels_, est.labels_)
        assert back.get_params() == est.get_params()
    assert back.n_clusters_ == est.n_clusters_


def _run(code, tmp_path):
    """Run ``code`` in a fresh interpreter (a segfault is a failure, not a
    crash of the test session); returns its stdout."""
    script = tmp_path / "script.py"
    script.write_text(textwrap.dedent(code))
    done = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, (done.returncode, done.stdout, done.stderr[-3000:])
    return done.stdout


_FOREST = """
    import numpy as np
    from sklearn.ensemble import RandomForestClassifier
    from sklearn.pipeline import make_pipeline
    from skpcd.datasets import make_urban_objects
    from skpcd.features import ShapeFeatures

    clouds, labels = make_urban_objects(n_per_class=3, random_state=0)
    forest = RandomForestClassifier(n_estimators=4, random_state=0)
    model = make_pipeline(ShapeFeatures(), forest).fit(clouds, labels)
"""


def test_bit_flips_are_caught_by_the_checksum_never_a_crash(tmp_path):
    # was: 12 of 120 single-bit flips of a joblib model segfaulted in predict
    out = _run(
        _FOREST
        + f"""
    import collections, json, pathlib
    from skpcd.exceptions import PointCloudFileError
    from skpcd.io import load_model, save_model
    from skpcd.io._model import _DIGEST, _PREFIX

    tmp = pathlib.Path({str(tmp_path)!r})
    outcomes = collections.Counter()
    rng = np.random.default_rng(0)
    for fmt in ("skops", "joblib"):
        good = save_model(model, tmp / f"good.{{fmt}}", format=fmt).read_bytes()
        length = int.from_bytes(good[16:24], "little")
        payload = _PREFIX + length + _DIGEST
        # every byte up to the payload, and 150 bytes of the payload
        where = [*range(payload), *rng.integers(payload, len(good), 150)]
        for at in where:
            data = bytearray(good)
            data[at] ^= 1 << int(rng.integers(8))
            path = tmp / f"flip.{{fmt}}"
            path.write_bytes(bytes(data))
            try:
                load_model(path, trust_pickle=True).predict(clouds)
                outcomes["loaded"] += 1
            except PointCloudFileError as exc:
                assert str(exc).startswith(str(path)), exc
                text = str(exc)[len(str(path)) :]
                outcomes["checksum" if "checksum" in text else text] += 1
    print(json.dumps(outcomes))
    """,
        tmp_path,
    )
    outcomes = json.loads(out)
    assert "loaded" not in outcomes
    assert sum(outcomes.values()) > 2 * 150 + 600
    # all but a few flips (signature, header length) are checksum errors
    assert outcomes["checksum"] > 0.9 * sum(outcomes.values()), outcomes


def test_crafted_trees_are_refused_before_predict(tmp_path):
    # with valid checksums (a file made to harm, not a corrupt one): node
    # indices that scikit-learn follows unchecked, a cycle that would hang
    out = _run(
        _FOREST
        + f"""
    import pathlib
    from sklearn.tree._tree import Tree
    from skpcd.exceptions import PointCloudFileError
    from skpcd.io import load_model, save_model

    tmp = pathlib.Path({str(tmp_path)!r})

    def crafted(edit, n_features=None):
        tree = forest.estimators_[0].tree_
        state = tree.__getstate__()
        nodes = state["nodes"].copy()
        edit(nodes)
        n, classes, outputs = tree.__reduce__()[1]
        bad = Tree(n_features or n, classes, outputs)
        bad.__setstate__(dict(state, nodes=nodes))
        good, forest.estimators_[0].tree_ = forest.estimators_[0].tree_, bad
        try:
            return save_model(model, tmp / "crafted.skpcd", overwrite=True)
        finally:
            forest.estimators_[0].tree_ = good

    def child_out_of_range(nodes):
        nodes["left_child"][0] = 10**6

    def feature_out_of_range(nodes):
        nodes["feature"][0] = 10**6

    def cycle(nodes):  # an inner node's child pointing back at the root
        inner = np.flatnonzero(nodes["left_child"] != -1)
        nodes["left_child"][inner[1]] = 0

    def one_child(nodes):
        nodes["left_child"][0] = -1

    edits = [child_out_of_range, feature_out_of_range, cycle, one_child]
    for edit in edits:
        what = edit.__name__
        path = crafted(edit)
        try:
            load_model(path)
        except PointCloudFileError as exc:
            assert "decision tree" in str(exc), exc
            print(what, "refused")
        else:
            raise AssertionError(what + " was loaded")
    path = crafted(lambda nodes: None, n_features=1000)
    try:
        load_model(path)
    except PointCloudFileError as exc:
        assert "expects 1000 features" in str(exc), exc
        print("n_features refused")
    print(list(load_model(save_model(model, tmp / "fine.skpcd")).predict(clouds[:2])))
    """,
        tmp_path,
    )
    assert out.count("refused") == 5, out


def _forest_pipeline():
    from skpcd.datasets import make_urban_objects
    from skpcd.features import ShapeFeatures

    clouds, labels = make_urban_objects(n_per_class=3, random_state=0)
    forest = RandomForestClassifier(n_estimators=4, random_state=0)
    return make_pipeline(ShapeFeatures(), forest).fit(clouds, labels), clouds


def _retree(tree, n_features=None, values=None, nodes=None):
    """A copy of a fitted ``Tree`` with other sizes or arrays."""
    from sklearn.tree._tree import Tree

    state = tree.__getstate__()
    n, classes, outputs = tree.__reduce__()[1]
    if values is not None:
        classes = np.full(outputs, values.shape[2], dtype=np.intp)
    new = Tree(n_features or n, classes, outputs)
    new.__setstate__(
        dict(
            state,
            nodes=state["nodes"] if nodes is None else nodes,
            values=state["values"] if values is None else values,
        )
    )
    return new


def _short_classes(forest):
    forest.classes_ = forest.classes_[:2]


def _long_classes(forest):
    forest.classes_ = np.r_[forest.classes_, ["x", "y"]]


def _fewer_n_classes(forest):
    forest.n_classes_ = 2


def _tree_of_two_classes(forest):
    tree = forest.estimators_[0]
    values = np.ascontiguousarray(tree.tree_.__getstate__()["values"][:, :, :2])
    tree.tree_ = _retree(tree.tree_, values=values)
    tree.classes_, tree.n_classes_ = tree.classes_[:2], 2


def _nan_leaves(forest):
    tree = forest.estimators_[0]
    values = tree.tree_.__getstate__()["values"].copy()
    values[:] = np.nan
    tree.tree_ = _retree(tree.tree_, values=values)


def _no_trees(forest):
    forest.estimators_ = []


def _two_outputs(forest):
    forest.n_outputs_ = 2


def _descriptor_width(forest):
    # the forest and its trees agree on 3 features; ShapeFeatures gives 18
    forest.n_features_in_ = 3
    for tree in forest.estimators_:
        nodes = tree.tree_.__getstate__()["nodes"].copy()
        inner = nodes["feature"] >= 0
        nodes["feature"][inner] %= 3
        tree.tree_ = _retree(tree.tree_, n_features=3, nodes=nodes)
        tree.n_features_in_ = 3


_STRUCTURE_EDITS = {
    _short_classes: "has [2] classes_ but n_classes_ says [5]",
    _long_classes: "has [7] classes_ but n_classes_ says [5]",
    _fewer_n_classes: "has [5] classes_ but n_classes_ says [2]",
    _tree_of_two_classes: "tells [2] classes, its estimator [5]",
    _nan_leaves: "leaf values that are not finite",
    _no_trees: "RandomForestClassifier holds no estimators",
    _two_outputs: "has 1 outputs, its estimator 2",
    _descriptor_width: "ShapeFeatures gives 18 features but the "
    "RandomForestClassifier after it expects 3",
}


@pytest.mark.parametrize("edit", _STRUCTURE_EDITS, ids=lambda e: e.__name__)
def test_crafted_structure_is_refused_when_loading(tmp_path, edit):
    # issue 29 item 14: such files, with valid checksums, loaded and then
    # failed in predict with scikit-learn's IndexError or ValueError (or
    # answered with wrong classes)
    model, clouds = _forest_pipeline()
    expected = model.predict(clouds)
    edit(model[-1])
    try:  # the harm: scikit-learn's error in predict, or answers that do not fit
        proba, answer = model.predict_proba(clouds), model.predict(clouds)
    except (IndexError, ValueError):
        pass
    else:
        assert (
            not np.array_equal(answer, expected)
            or not np.isfinite(proba).all()
            or proba.shape[1] != len(model.classes_)
        )
    path = save_model(model, tmp_path / "crafted.skpcd")
    with pytest.raises(PointCloudFileError) as info:
        load_model(path)
    text = str(info.value)
    assert text.startswith(f"{path}: corrupt model: ") and "\n" not in text
    assert _STRUCTURE_EDITS[edit] in text


@pytest.mark.parametrize("multi", [False, True])
def test_sound_ensembles_pass_the_structure_check(tmp_path, multi):
    from sklearn.ensemble import (
        AdaBoostClassifier,
        ExtraTreesRegressor,
        GradientBoostingClassifier,
    )
    from sklearn.tree import DecisionTreeClassifier

    rng = np.random.default_rng(0)
    X, y = rng.random((60, 4)), np.arange(60) % 3
    target = np.column_stack([y, y % 2]) if multi else y
    models = [
        RandomForestClassifier(n_estimators=3, random_state=0).fit(X, target),
        DecisionTreeClassifier(random_state=0).fit(X, target),
        ExtraTreesRegressor(n_estimators=3, random_state=0).fit(X, target),
    ]
    if not multi:
        models += [
            GradientBoostingClassifier(n_estimators=3, random_state=0).fit(X, y),
            AdaBoostClassifier(n_estimators=3, random_state=0).fit(X, y),
        ]
    for model in models:
        back = load_model(save_model(model, tmp_path / "m.skpcd", overwrite=True))
        np.testing.assert_array_equal(back.predict(X), model.predict(X))


def test_skops_is_loaded_without_importing_every_estimator(tmp_path):
    # issue 28 item 4: skops lists every scikit-learn estimator when it is
    # imported (sklearn.utils.all_estimators imports all of scikit-learn,
    # a third of the street model's loading time); skpcd needs only those
    # the file names. Other users of skops in the process still get its list.
    out = _run(
        """
    import json, sys
    import numpy as np
    from skpcd.classification import load_street_model

    model = load_street_model()
    every = ("sklearn.cross_decomposition", "sklearn.semi_supervised")
    before = [name in sys.modules for name in every]
    import skops.io
    from sklearn.linear_model import LogisticRegression
    from sklearn.utils import all_estimators

    X, y = np.random.default_rng(0).random((30, 3)), np.arange(30) % 2
    other = LogisticRegression().fit(X, y)
    back = skops.io.loads(skops.io.dumps(other))  # skops' own default trust
    names = skops.io._general.SKLEARN_ESTIMATOR_TYPE_NAMES
    expected = sorted(
        f"{c.__module__}.{c.__name__}" for _, c in all_estimators()
        if c.__module__.startswith("sklearn.")
    )
    print(json.dumps({
        "imported": before,
        "same": bool((back.predict(X) == other.predict(X)).all()),
        "names": sorted(names) == expected and len(names) > 150,
    }))
    """,
        tmp_path,
    )
    result = json.loads(out.strip().splitlines()[-1])
    assert result == {"imported": [False, False], "same": True, "names": True}


def test_trusted_estimators_are_those_of_all_estimators():
    # the rule skpcd asks of the types a file names agrees with the list
    # skops makes from sklearn.utils.all_estimators, on every class of every
    # scikit-learn module
    import inspect
    import sys

    from sklearn.utils import all_estimators

    listed = {
        f"{c.__module__}.{c.__name__}"
        for _, c in all_estimators()
        if c.__module__.startswith("sklearn.")
    }
    classes = {
        f"{c.__module__}.{c.__name__}"
        for name, module in list(sys.modules.items())
        if name.startswith("sklearn") and module is not None
        for _, c in inspect.getmembers(module, inspect.isclass)
    }
    assert len(classes) > 500 and listed <= classes
    assert {n for n in classes if checks._sklearn_estimator(n)} == listed
    for name in ("os.system", "sklearn.base.clone", "sklearn.foo.Bar", "sklearn."):
        assert not checks._sklearn_estimator(name)


def test_street_model_loads_as_skops_builds_it():
    # the same model as skops.io.loads with its own default trust builds
    import skops.io

    from skpcd.classification._street import STREET_MODEL_PATH

    model, info = load_model(STREET_MODEL_PATH, return_info=True, check_versions=False)
    _, payload = _split(STREET_MODEL_PATH.read_bytes())
    plain = skops.io.loads(payload, trusted=list(m.TRUSTED_TYPES))
    clouds = [np.asarray(c, dtype=float) for c in info["metadata"]["probe"]["clouds"]]
    np.testing.assert_array_equal(
        model.predict_proba(clouds), plain.predict_proba(clouds)
    )
    assert repr(model) == repr(plain)
