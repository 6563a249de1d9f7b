import joblib
import numpy as np
import pytest
from sklearn.dummy import DummyClassifier

import skpcd
from skpcd.exceptions import IncompatibleModelError, MissingFileError
from skpcd.io import _model as m
from skpcd.io import load_model, save_model


def _model():
    return DummyClassifier(strategy="most_frequent").fit([[0], [1], [2]], list("aab"))


def test_round_trip_keeps_model_versions_and_metadata(tmp_path):
    path = save_model(_model(), tmp_path / "m.joblib", metadata={"data": "toy"})
    model, info = load_model(path, return_info=True)
    assert model.predict([[5]]).tolist() == ["a"]
    assert info["metadata"] == {"data": "toy"}
    assert info["versions"]["skpcd"] == skpcd.__version__
    import sklearn

    assert info["versions"]["scikit-learn"] == sklearn.__version__


def test_existing_file_is_kept_unless_overwrite(tmp_path):
    path = tmp_path / "m.joblib"
    path.write_text("keep me")
    with pytest.raises(FileExistsError, match="overwrite=True"):
        save_model(_model(), path)
    assert path.read_text() == "keep me"
    save_model(_model(), path, overwrite=True)
    assert load_model(path).predict([[0]]).tolist() == ["a"]
    assert [p.name for p in tmp_path.iterdir()] == ["m.joblib"]  # no temp file left


@pytest.mark.parametrize("lib", ["skpcd", "scikit-learn"])
def test_model_from_another_release_is_refused(tmp_path, monkeypatch, lib):
    path = save_model(_model(), tmp_path / "m.joblib")
    real = m._versions()
    other = dict(real, **{lib: "99.1.0"})
    monkeypatch.setattr(m, "_versions", lambda: other)
    with pytest.raises(IncompatibleModelError, match=rf"written with {lib} .*99\.1\.0"):
        load_model(path)
    # a patch release of the same major.minor is accepted
    patch = [*real[lib].split(".")[:2], "999"]
    monkeypatch.setattr(m, "_versions", lambda: dict(real, **{lib: ".".join(patch)}))
    assert load_model(path).predict([[0]]).tolist() == ["a"]
    monkeypatch.setattr(m, "_versions", lambda: other)
    assert load_model(path, check_versions=False) is not None


def test_not_a_model_file(tmp_path):
    with pytest.raises(MissingFileError):
        load_model(tmp_path / "none.joblib")
    junk = tmp_path / "junk.joblib"
    junk.write_bytes(b"\x00garbage")
    with pytest.raises(ValueError, match="not a model file"):
        load_model(junk)
    other = tmp_path / "other.joblib"
    joblib.dump(np.arange(3), other)
    with pytest.raises(ValueError, match="not a model file written by skpcd"):
        load_model(other)
