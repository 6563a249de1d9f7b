"""Identification of the DALES objects: both papers' experiments, and the best pipeline.

Four experiments on ``../shared/data/dales_objects`` (399 objects, 5 classes), all with
the same repeated 5-fold stratified cross-validation (``--repeats`` repeats, mean and
standard deviation over the folds). Nothing is tuned on a test fold: a tuned choice
(SVM ``C``, QDA ``reg_param``, tree leaf size, the case-based ``w1``, the two-step
grouping, the selected pipeline) is made by an inner cross-validation inside the
training folds.

1. He et al. (2017), seed 001: per-point PFH (k = 6, and radius 0.5 m) -> bag of
   features with 15/30/50/100 words (raw counts as in the paper, and word frequencies)
   -> SVM (RBF, standardised), random forest (100 trees), decision tree, quadratic
   discriminant (regularised). The per-point PFH is computed once per cloud and cached
   (it learns nothing); the vocabulary is learned inside every training fold.
2. One-step versus two-step (:class:`~skpcd.classification.TwoStepClassifier`) on the
   full set and on an imbalanced subsample where the two classes of one group are rare.
3. Wang et al. (2023), seed 000: case-based identification
   (:class:`~skpcd.classification.CaseBasedClassifier`), classic (mean-pooled) versus
   improved PFH and FPFH, with and without the volume term, threshold None and 0.8.
4. Pipelines built from the library's pieces, compared with the default
   (:func:`~skpcd.classification.make_default_pipeline`, shape features + random
   forest of 300 trees), and a nested cross-validation of "pick the best by inner CV".

Usage::

    python benchmarks/bench_identification.py --quick        # a few minutes
    python benchmarks/bench_identification.py                 # about 30-40 minutes

writes ``benchmarks/results/identification.json`` and ``identification.txt``
(``identification_quick.*`` with ``--quick``). Descriptors are cached in
``--cache`` (default ``/tmp/skpcd_identification_cache``).
"""

import argparse
import hashlib
import json
import os
import platform
import time
import warnings
from pathlib import Path

import numpy as np
from measure import provenance

ROOT = Path(__file__).resolve().parent
DEFAULT_DATA = os.environ.get(
    "SKPCD_DALES_DIR", str(ROOT.parents[1] / "shared" / "data" / "dales_objects")
)
DEFAULT_CACHE = "/tmp/skpcd_identification_cache"

# The a-priori grouping for the two-step experiment: tall, narrow, vertical objects.
# In aerial LiDAR a pole (with its lamp or sign head) and a small tree are both a
# vertical stem with something on top, seen mostly from above.
A_PRIORI_GROUPS = {"vertical": ["pole", "tree"]}
# The second grouping: the pair that the inner-CV confusions of the one-step bag of
# features (in the training folds of the full set) found most often (12 of 15 folds).
GROUPINGS = {
    "{pole, tree}": A_PRIORI_GROUPS,
    "{fence, tree}": {"fence/tree": ["fence", "tree"]},
}
# The two-step experiment: the full set, then subsamples where a group's classes are
# rare (``n_rare`` of each in a training fold of 320 objects, 64 of every other class).
TWO_STEP_SETTINGS = {
    "full": None,
    "imbalanced, pole and tree rare": ["pole", "tree"],
    "imbalanced, fence and tree rare": ["fence", "tree"],
}
# k-means (n_init=1) learns each vocabulary from this many descriptors drawn from the
# training clouds (the library default, 100 000, takes about a minute per 100-word
# vocabulary on this machine; every descriptor is still counted in the encoding).
MAX_DESCRIPTORS = 20_000


# ---------------------------------------------------------------------------
# data and cached descriptors


def load(folder, quick, seed=0):
    from skpcd.io import read_segments

    folder = Path(folder)
    clouds, labels, names = read_segments(folder, folder / "labels.csv")
    if quick:  # 16 objects per class
        rng = np.random.RandomState(seed)
        keep = np.sort(
            np.concatenate(
                [
                    rng.choice(np.flatnonzero(labels == c), 16, replace=False)
                    for c in np.unique(labels)
                ]
            )
        )
        clouds = [clouds[i] for i in keep]
        labels, names = labels[keep], [names[i] for i in keep]
    return clouds, np.asarray(labels), list(names)


def _key(names, clouds, what):
    h = hashlib.sha1(what.encode())
    for n, c in zip(names, clouds):
        h.update(f"{n}:{len(c)}:{float(c[:, :3].sum()):.6f};".encode())
    return h.hexdigest()[:16]


def cached_local(cache, names, clouds, name, make, n_jobs, timings):
    """Per-point descriptors of every cloud (a list of arrays), cached as .npz."""
    path = Path(cache) / f"{name}_{_key(names, clouds, name)}.npz"
    if path.is_file():
        z = np.load(path)
        data, offsets = z["data"], z["offsets"]
        timings[name] = float(z["seconds"])
    else:
        t = time.perf_counter()
        descs = make(n_jobs).fit_transform(clouds)
        timings[name] = time.perf_counter() - t
        offsets = np.concatenate([[0], np.cumsum([len(d) for d in descs])])
        data = np.concatenate(descs).astype(np.float32)
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez(path, data=data, offsets=offsets, seconds=timings[name])
    return [data[offsets[i] : offsets[i + 1]] for i in range(len(offsets) - 1)]


def segment_descriptors(n_jobs):
    """The segment-level descriptors: name -> (transformer, post-processing)."""
    from skpcd.features import (
        FPFHTransformer,
        ImprovedPFHTransformer,
        OverallDescriptor,
        PFHTransformer,
        ShapeFeatures,
    )

    return {
        "shape": ShapeFeatures(),
        "overall": OverallDescriptor(),
        "improved_pfh": ImprovedPFHTransformer(undefined="zero", n_jobs=n_jobs),
        "improved_fpfh": ImprovedPFHTransformer(
            "fpfh", undefined="zero", n_jobs=n_jobs
        ),
        "improved_pfh_r09": ImprovedPFHTransformer(
            radius=0.9, undefined="zero", n_jobs=n_jobs
        ),
        "mean_pfh": PFHTransformer(pooling="mean", n_jobs=n_jobs),
        "mean_fpfh": FPFHTransformer(pooling="mean", n_jobs=n_jobs),
    }


def cached_segment(cache, names, clouds, n_jobs, timings):
    out = {}
    for name, est in segment_descriptors(n_jobs).items():
        path = Path(cache) / f"seg_{name}_{_key(names, clouds, name)}.npz"
        if path.is_file():
            z = np.load(path)
            out[name], timings[name] = z["X"], float(z["seconds"])
            continue
        t = time.perf_counter()
        X = np.asarray(est.fit_transform(clouds), dtype=np.float64)
        timings[name] = time.perf_counter() - t
        # a cloud without any defined descriptor: a zero histogram (S_a = 0)
        X = np.where(np.isfinite(X), X, 0.0)
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez(path, X=X, seconds=timings[name])
        out[name] = X
    return out


# ---------------------------------------------------------------------------
# classifiers


def _inner(seed=0):
    from sklearn.model_selection import StratifiedKFold

    return StratifiedKFold(3, shuffle=True, random_state=seed)


def make_classifier(name, n_jobs, class_weight=None):
    from sklearn.discriminant_analysis import QuadraticDiscriminantAnalysis
    from sklearn.ensemble import HistGradientBoostingClassifier, RandomForestClassifier
    from sklearn.model_selection import GridSearchCV
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler
    from sklearn.svm import SVC
    from sklearn.tree import DecisionTreeClassifier

    if name == "SVM":  # RBF kernel, gamma="scale"; C by inner 3-fold CV
        return GridSearchCV(
            make_pipeline(StandardScaler(), SVC(class_weight=class_weight)),
            {"svc__C": [1.0, 10.0, 100.0]},
            cv=_inner(),
        )
    if name == "RF100":
        return RandomForestClassifier(
            100, class_weight=class_weight, random_state=0, n_jobs=n_jobs
        )
    if name == "RF300":
        return RandomForestClassifier(
            300, class_weight=class_weight, random_state=0, n_jobs=n_jobs
        )
    if name == "DT":  # minimum leaf size (the paper's 13 among others) by inner CV
        return GridSearchCV(
            DecisionTreeClassifier(class_weight=class_weight, random_state=0),
            {"min_samples_leaf": [1, 5, 13]},
            cv=_inner(),
        )
    if name == "QDA":  # word counts are collinear, a class has fewer samples than
        # 100 words: shrunk class covariances, the shrinkage by inner CV
        return GridSearchCV(
            make_pipeline(
                StandardScaler(), QuadraticDiscriminantAnalysis(solver="eigen")
            ),
            {"quadraticdiscriminantanalysis__shrinkage": [0.1, 0.5, 0.9]},
            cv=_inner(),
        )
    if name == "HGB":
        return HistGradientBoostingClassifier(class_weight=class_weight, random_state=0)
    raise ValueError(name)


# ---------------------------------------------------------------------------
# bookkeeping


class Record:
    """Out-of-fold predictions of one configuration, per repeat."""

    def __init__(self, y, n_repeats):
        self.y = y
        self.pred = np.full((n_repeats, len(y)), None, dtype=object)
        self.fold_acc = []
        self.seconds = 0.0
        self.extra = {}

    def add(self, repeat, test, pred, seconds=0.0):
        pred = np.asarray(pred, dtype=object)
        self.pred[repeat, test] = pred
        self.fold_acc.append(float(np.mean(pred == self.y[test])))
        self.seconds += seconds

    def summary(self, classes):
        acc = np.array(self.fold_acc)
        out = {
            "accuracy_mean": float(acc.mean()),
            "accuracy_std": float(acc.std()),
            "fold_accuracy": acc.round(4).tolist(),
            "fit_predict_seconds": round(self.seconds, 2),
        }
        rec, prec, ident, answered, bal = [], [], [], [], []
        for r in range(len(self.pred)):
            seen = np.array([v is not None for v in self.pred[r]])
            if not seen.any():
                continue
            p, y = self.pred[r][seen], self.y[seen]
            rec.append([np.mean(p[y == c] == c) for c in classes])
            n_id = [np.sum(p == c) for c in classes]
            ok = [np.sum((p == c) & (y == c)) for c in classes]
            prec.append([o / n if n else np.nan for o, n in zip(ok, n_id)])
            ident.append(n_id)
            answered.append(p)
            bal.append(np.mean(rec[-1]))
        if rec:
            out["balanced_accuracy_mean"] = float(np.mean(bal))
            out["recall"] = _per_class(classes, rec)
            out["precision"] = _per_class(classes, prec)
            out["n_identified"] = dict(
                zip(classes, np.mean(ident, axis=0).round(1).tolist())
            )
            out["unknown_rate"] = float(np.mean(np.concatenate(answered) == "unknown"))
        out.update(self.extra)
        return out


def _per_class(classes, rows):
    a = np.array(rows, dtype=float)
    return {
        c: [round(float(m), 4), round(float(s), 4)]
        for c, m, s in zip(classes, np.nanmean(a, 0), np.nanstd(a, 0))
    }


def splits(y, n_repeats, seed=0):
    from sklearn.model_selection import RepeatedStratifiedKFold

    cv = RepeatedStratifiedKFold(n_splits=5, n_repeats=n_repeats, random_state=seed)
    return [
        (i // 5, tr, te) for i, (tr, te) in enumerate(cv.split(np.zeros(len(y)), y))
    ]


def log(*a):
    print(time.strftime("%H:%M:%S"), *a, flush=True)


# ---------------------------------------------------------------------------
# experiment 1: PFH -> bag of features -> classifiers


def experiment_bof(local, y, folds, vocab, classifiers, n_jobs, n_repeats):
    from sklearn.base import clone
    from sklearn.preprocessing import normalize

    from skpcd.encoding import BagOfFeatures

    classes = np.unique(y).tolist()
    records, bof_cache, bof_seconds = {}, {}, {}
    for dname, descs in local.items():
        for k, (rep, tr, te) in enumerate(folds):
            for n_words in vocab:
                t = time.perf_counter()
                bof = BagOfFeatures(
                    n_words,
                    max_descriptors=MAX_DESCRIPTORS,
                    norm=None,
                    random_state=k,
                    n_jobs=1,
                )  # raw counts (the paper); the frequencies are these, l1-normalised
                Xtr = bof.fit_transform([descs[i] for i in tr])
                Xte = bof.transform([descs[i] for i in te])
                dt = time.perf_counter() - t
                bof_seconds.setdefault((dname, n_words), []).append(dt)
                for norm in ("counts", "l1"):
                    A, B = Xtr, Xte
                    if norm == "l1":
                        A, B = normalize(Xtr, "l1"), normalize(Xte, "l1")
                    bof_cache[dname, n_words, norm, k] = (A, B)
                    for cname in classifiers:
                        key = (dname, norm, n_words, cname)
                        rec = records.setdefault(key, Record(y, n_repeats))
                        t = time.perf_counter()
                        with warnings.catch_warnings():
                            warnings.simplefilter("ignore")
                            clf = clone(make_classifier(cname, n_jobs)).fit(A, y[tr])
                            pred = clf.predict(B)
                        rec.add(rep, te, pred, time.perf_counter() - t)
            log(f"  bof {dname} fold {k + 1}/{len(folds)}")
    table = []
    for (dname, norm, n_words, cname), rec in records.items():
        s = rec.summary(classes)
        s.update(descriptor=dname, encoding=norm, n_words=n_words, classifier=cname)
        s["bof_seconds_per_fold"] = round(
            float(np.mean(bof_seconds[dname, n_words])), 2
        )
        table.append(s)
    return table, bof_cache


# ---------------------------------------------------------------------------
# experiment 2: one step versus two steps


def make_confusion_two_step(n_jobs, cname):
    from sklearn.base import BaseEstimator, ClassifierMixin, clone
    from sklearn.metrics import confusion_matrix
    from sklearn.model_selection import cross_val_predict

    from skpcd.classification import TwoStepClassifier

    class ConfusionTwoStep(ClassifierMixin, BaseEstimator):
        """Two steps, grouping the pair of classes most confused by the one-step
        classifier in an inner 3-fold CV of the training data."""

        def __init__(self, estimator):
            self.estimator = estimator

        def fit(self, X, y):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                p = cross_val_predict(clone(self.estimator), X, y, cv=_inner(1))
            classes = np.unique(y)
            cm = confusion_matrix(y, p, labels=classes).astype(float)
            cm /= cm.sum(axis=1, keepdims=True)  # row: fraction of a class
            sym = cm + cm.T
            np.fill_diagonal(sym, -1)
            i, j = np.unravel_index(np.argmax(sym), sym.shape)
            self.groups_ = {"group": sorted([classes[i], classes[j]])}
            self.model_ = TwoStepClassifier(
                clone(self.estimator), clone(self.estimator), groups=self.groups_
            ).fit(X, y)
            self.classes_ = self.model_.classes_
            return self

        def predict(self, X):
            return self.model_.predict(X)

    return ConfusionTwoStep(make_classifier(cname, n_jobs))


def experiment_two_step(feats, y, folds, n_jobs, n_repeats, n_rare, classifiers):
    """feats: name -> function(k, tr, te) -> (Xtr, Xte)."""
    from skpcd.classification import TwoStepClassifier

    classes = np.unique(y).tolist()
    table = []
    for setting, rare in TWO_STEP_SETTINGS.items():
        for fname, get in feats.items():
            for cname in classifiers:
                models = {
                    "one-step": lambda c=cname: make_classifier(c, n_jobs),
                    "one-step, balanced weights": lambda c=cname: make_classifier(
                        c, n_jobs, class_weight="balanced"
                    ),
                    **{
                        f"two-step {g}": lambda c=cname, groups=groups: (
                            TwoStepClassifier(
                                make_classifier(c, n_jobs),
                                make_classifier(c, n_jobs),
                                groups=groups,
                            )
                        )
                        for g, groups in GROUPINGS.items()
                    },
                    "two-step, grouping from inner-CV confusions": (
                        lambda c=cname: make_confusion_two_step(n_jobs, c)
                    ),
                }
                recs = {m: Record(y, n_repeats) for m in models}
                found = []
                for k, (rep, tr, te) in enumerate(folds):
                    Xtr, Xte = get(k, tr, te)
                    tr_idx = np.arange(len(tr))
                    te_idx = np.arange(len(te))
                    if rare is not None:
                        rng = np.random.RandomState(k)  # same subsample for all
                        # the same rare subsample of the group for every model: keep
                        # n_rare of each rare class in training and 1/5 of that in test
                        keep_tr, keep_te = [], []
                        for c in classes:
                            a = np.flatnonzero(y[tr] == c)
                            b = np.flatnonzero(y[te] == c)
                            if c in rare:
                                a = rng.choice(a, n_rare, replace=False)
                                b = rng.choice(b, max(n_rare // 4, 1), replace=False)
                            keep_tr.append(a)
                            keep_te.append(b)
                        tr_idx = np.sort(np.concatenate(keep_tr))
                        te_idx = np.sort(np.concatenate(keep_te))
                    for m, make in models.items():
                        t = time.perf_counter()
                        with warnings.catch_warnings():
                            warnings.simplefilter("ignore")
                            clf = make().fit(Xtr[tr_idx], y[tr][tr_idx])
                            pred = clf.predict(Xte[te_idx])
                        recs[m].add(rep, te[te_idx], pred, time.perf_counter() - t)
                        if hasattr(clf, "groups_") and isinstance(clf.groups_, dict):
                            found.append("+".join(clf.groups_["group"]))
                for m, rec in recs.items():
                    s = rec.summary(classes)
                    s.update(setting=setting, features=fname, classifier=cname, model=m)
                    if m.startswith("two-step, grouping") and found:
                        u, n = np.unique(found, return_counts=True)
                        s["groups_found"] = dict(zip(u.tolist(), n.tolist()))
                    table.append(s)
                log(f"  two-step {setting} {fname} {cname}")
    return table


# ---------------------------------------------------------------------------
# experiment 3: case-based identification


def experiment_case_based(seg, y, folds, n_repeats):
    from sklearn.model_selection import GridSearchCV

    from skpcd.classification import CaseBasedClassifier

    classes = np.unique(y).tolist()
    volume = seg["overall"][:, 9:10]  # OverallDescriptor column "volume"
    descriptors = {
        "classic PFH (mean-pooled, k=10)": seg["mean_pfh"],
        "improved PFH (k=10)": seg["improved_pfh"],
        "improved PFH (r=0.9 m)": seg["improved_pfh_r09"],
        "classic FPFH (mean-pooled, k=10)": seg["mean_fpfh"],
        "improved FPFH (k=10)": seg["improved_fpfh"],
    }
    table = []
    for dname, H in descriptors.items():
        for use_volume in (False, True):
            X = np.hstack([volume, H]) if use_volume else H
            col = 0 if use_volume else None
            variants = {"None": None, "0.8": 0.8}
            if use_volume:
                variants["None, w1 by inner CV"] = "tuned"
            for thr_name, thr in variants.items():
                rec = Record(y, n_repeats)
                chosen = []
                for rep, tr, te in folds:
                    t = time.perf_counter()
                    if thr == "tuned":
                        clf = GridSearchCV(
                            CaseBasedClassifier(volume_column=col, threshold=None),
                            {"w1": [0.005, 0.01, 0.02, 0.05, 0.1, 0.25, 0.5]},
                            cv=_inner(),
                        ).fit(X[tr], y[tr])
                        chosen.append(clf.best_params_["w1"])
                    else:
                        clf = CaseBasedClassifier(volume_column=col, threshold=thr)
                        clf.fit(X[tr], y[tr])
                    rec.add(rep, te, clf.predict(X[te]), time.perf_counter() - t)
                s = rec.summary(classes)
                if chosen:
                    u, n = np.unique(chosen, return_counts=True)
                    s["w1_chosen"] = {str(a): int(b) for a, b in zip(u, n)}
                s.update(descriptor=dname, volume=use_volume, threshold=thr_name)
                table.append(s)
        log(f"  case-based {dname}")
    return table


# ---------------------------------------------------------------------------
# experiment 4: the best pipeline


def _blocks(seg):
    return {
        "shape": seg["shape"],
        "improved_fpfh": seg["improved_fpfh"],
        "improved_pfh": seg["improved_pfh"],
        "mean_fpfh": seg["mean_fpfh"],
        "mean_pfh": seg["mean_pfh"],
    }


FEATURE_SETS = {
    "shape": ["shape"],
    "shape + improved FPFH": ["shape", "improved_fpfh"],
    "shape + improved PFH": ["shape", "improved_pfh"],
    "shape + mean FPFH": ["shape", "mean_fpfh"],
    "shape + mean PFH": ["shape", "mean_pfh"],
    "improved FPFH": ["improved_fpfh"],
    "improved PFH": ["improved_pfh"],
    "mean FPFH": ["mean_fpfh"],
}


def experiment_best(
    seg, y, folds, bof_cache, bof_key, n_jobs, n_repeats, clfs, only_bof=False
):
    from sklearn.base import clone

    classes = np.unique(y).tolist()
    blocks = _blocks(seg)
    table = []

    def run(name, cname, get):
        rec = Record(y, n_repeats)
        for k, (rep, tr, te) in enumerate(folds):
            Xtr, Xte = get(k, tr, te)
            t = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                clf = clone(make_classifier(cname, n_jobs)).fit(Xtr, y[tr])
                pred = clf.predict(Xte)
            rec.add(rep, te, pred, time.perf_counter() - t)
        s = rec.summary(classes)
        s.update(features=name, classifier=cname)
        table.append(s)
        log(f"  best: {name} + {cname}: {s['accuracy_mean']:.4f}")

    for fname, parts in {} if only_bof else FEATURE_SETS.items():
        X = np.hstack([blocks[p] for p in parts])
        for cname in clfs:
            run(fname, cname, lambda k, tr, te, X=X: (X[tr], X[te]))
    if bof_cache is not None:
        bname = "shape + BoF({} {} words, {})".format(*bof_key)
        for cname in clfs:

            def get(k, tr, te):
                A, B = bof_cache[(*bof_key, k)]
                return (
                    np.hstack([blocks["shape"][tr], A]),
                    np.hstack([blocks["shape"][te], B]),
                )

            run(bname, cname, get)
    return table


def nested_selection(seg, y, folds, n_jobs, n_repeats):
    """Outer CV of: choose (feature set, classifier) by inner 3-fold CV, refit."""
    from sklearn.ensemble import HistGradientBoostingClassifier, RandomForestClassifier
    from sklearn.model_selection import GridSearchCV
    from sklearn.pipeline import Pipeline
    from sklearn.preprocessing import FunctionTransformer

    classes = np.unique(y).tolist()
    blocks = _blocks(seg)
    names = ["shape", "improved_fpfh", "improved_pfh", "mean_fpfh", "mean_pfh"]
    X = np.hstack([blocks[n] for n in names])
    bounds = np.cumsum([0] + [blocks[n].shape[1] for n in names])
    cols = {n: np.arange(bounds[i], bounds[i + 1]) for i, n in enumerate(names)}
    sets = [s for s in FEATURE_SETS.values() if "shape" in s]
    selections = [{"cols": np.concatenate([cols[p] for p in s]).tolist()} for s in sets]
    pipe = Pipeline(
        [
            ("select", FunctionTransformer(_take)),
            ("clf", RandomForestClassifier(300, random_state=0, n_jobs=n_jobs)),
        ]
    )
    grid = {
        "select__kw_args": selections,
        "clf": [
            RandomForestClassifier(300, random_state=0, n_jobs=n_jobs),
            HistGradientBoostingClassifier(random_state=0),
        ],
    }
    rec, chosen = Record(y, n_repeats), []
    for rep, tr, te in folds:
        t = time.perf_counter()
        gs = GridSearchCV(pipe, grid, cv=_inner()).fit(X[tr], y[tr])
        rec.add(rep, te, gs.predict(X[te]), time.perf_counter() - t)
        i = selections.index(gs.best_params_["select__kw_args"])
        chosen.append(
            " + ".join(sets[i]) + " / " + type(gs.best_params_["clf"]).__name__
        )
        log(f"  nested: chose {chosen[-1]}")
    s = rec.summary(classes)
    u, n = np.unique(chosen, return_counts=True)
    s["chosen"] = dict(zip(u.tolist(), n.tolist()))
    return s


def _take(X, cols):
    return X[:, cols]


def recommended_pipeline(n_jobs=None, histogram="mean_pfh"):
    """Shape features and one histogram of the segment, then a random forest.

    ``histogram="mean_pfh"`` (the recommendation): the classic PFH (k = 10) averaged
    over the points; ``"improved_fpfh"``: the improved FPFH of Wang et al.
    """
    from sklearn.ensemble import RandomForestClassifier
    from sklearn.pipeline import FeatureUnion, make_pipeline

    from skpcd.features import ImprovedPFHTransformer, PFHTransformer, ShapeFeatures

    if histogram == "mean_pfh":
        part = PFHTransformer(n_neighbors=10, pooling="mean", n_jobs=n_jobs)
    else:
        part = ImprovedPFHTransformer("fpfh", undefined="zero", n_jobs=n_jobs)
    return make_pipeline(
        FeatureUnion([("shape", ShapeFeatures()), (histogram, part)]),
        RandomForestClassifier(n_estimators=300, random_state=0, n_jobs=n_jobs),
    )


def time_pipelines(clouds, y, folds, n_jobs):
    """End to end on the clouds: fit on all + predict all, and one repeat of CV."""
    from sklearn.base import clone

    from skpcd.classification import make_default_pipeline

    out = {}
    for name, pipe in (
        ("default: ShapeFeatures + RF(300)", make_default_pipeline(n_jobs=n_jobs)),
        (
            "ShapeFeatures + mean PFH (k=10) + RF(300)",
            recommended_pipeline(n_jobs, "mean_pfh"),
        ),
        (
            "ShapeFeatures + improved FPFH + RF(300)",
            recommended_pipeline(n_jobs, "improved_fpfh"),
        ),
    ):
        t = time.perf_counter()
        pipe.fit(clouds, y)
        fit_s = time.perf_counter() - t
        t = time.perf_counter()
        pipe.predict(clouds)
        pred_s = time.perf_counter() - t
        acc = []
        for rep, tr, te in folds:
            if rep > 0:
                break
            m = clone(pipe).fit([clouds[i] for i in tr], y[tr])
            acc.append(float(np.mean(m.predict([clouds[i] for i in te]) == y[te])))
        out[name] = {
            "fit_seconds_all": round(fit_s, 2),
            "predict_seconds_all": round(pred_s, 2),
            "cv_repeat0_accuracy_on_clouds": round(float(np.mean(acc)), 4),
        }
        log(f"  timing {name}: {out[name]}")
    return out


# ---------------------------------------------------------------------------
# report


def _pm(m, s, pct=True):
    return f"{100 * m:5.1f} ± {100 * s:4.1f}" if pct else f"{m:.3f} ± {s:.3f}"


def write_text(res, path):
    L = []
    meta = res["meta"]
    L.append(f"skpcd identification benchmark, {meta['n_objects']} DALES objects")
    L.append(
        f"CV: {meta['cv']}; machine {meta['machine']}; n_jobs={meta['n_jobs']}; "
        f"total {meta['total_seconds']:.0f} s"
    )
    if "runs" in meta:
        L.append(meta["runs"])
    L.append("accuracy in %, mean ± std over the folds")
    L.append("")
    L.append("descriptor time (s, computed once, cached):")
    for k, v in meta["descriptor_seconds"].items():
        L.append(f"  {k:22s} {v:7.1f}")
    classes = meta["classes"]

    if "bof" in res:
        L += ["", "1. PFH -> bag of features -> classifier (seed 001, Figure 9)", ""]
        rows = res["bof"]
        clfs = sorted({r["classifier"] for r in rows}, key=_clf_order)
        vocab = sorted({r["n_words"] for r in rows})
        for dname in sorted({r["descriptor"] for r in rows}):
            for enc in ("counts", "l1"):
                L.append(f"  {dname}, encoding {enc}")
                L.append("    words  " + "".join(f"{c:>16s}" for c in clfs))
                for w in vocab:
                    cells = []
                    for c in clfs:
                        r = _find(rows, descriptor=dname, encoding=enc, n_words=w,
                                  classifier=c)  # fmt: skip
                        cells.append(
                            f"{_pm(r['accuracy_mean'], r['accuracy_std']):>16s}"
                        )
                    L.append(f"    {w:5d}  " + "".join(cells))
        best = max(rows, key=lambda r: r["accuracy_mean"])
        L.append("")
        L.append(
            f"  best (post hoc): {best['descriptor']}, {best['encoding']}, "
            f"{best['n_words']} words, {best['classifier']}: "
            f"{_pm(best['accuracy_mean'], best['accuracy_std'])}"
        )
        L += _per_class_lines(best, classes)
        L.append("  bag of features (fit + encode) per fold, seconds: " + ", ".join(
            sorted({f"{r['descriptor']} {r['n_words']}w {r['bof_seconds_per_fold']}"
                    for r in rows if r["classifier"] == clfs[0]
                    and r["encoding"] == "counts"})))  # fmt: skip

    if "two_step" in res:
        L += ["", "2. one step versus two steps (recall per class, %)", ""]
        for r in res["two_step"]:
            head = (
                f"  [{r['setting']}] {r['features']} / {r['classifier']} / "
                f"{r['model']}: acc {_pm(r['accuracy_mean'], r['accuracy_std'])}, "
                f"balanced {100 * r['balanced_accuracy_mean']:.1f}"
            )
            if "groups_found" in r:
                head += f"  groups found {r['groups_found']}"
            L.append(head)
            L.append(
                "      recall "
                + "  ".join(f"{c} {100 * r['recall'][c][0]:5.1f}" for c in classes)
            )
            L.append(
                "      prec.  "
                + "  ".join(f"{c} {100 * r['precision'][c][0]:5.1f}" for c in classes)
            )

    if "case_based" in res:
        L += ["", "3. case-based identification (seed 000, Table 3)", ""]
        L.append(
            f"  {'descriptor':34s} {'volume':6s} {'threshold':22s} {'accuracy':>14s} "
            f"{'unknown':>8s}  " + " ".join(f"{c[:8]:>8s}" for c in classes)
        )
        for r in res["case_based"]:
            L.append(
                f"  {r['descriptor']:34s} {r['volume']!s:6s} {r['threshold']:22s} "
                f"{_pm(r['accuracy_mean'], r['accuracy_std']):>14s} "
                f"{100 * r['unknown_rate']:7.1f}%  "
                + " ".join(f"{100 * r['recall'][c][0]:8.1f}" for c in classes)
                + ("  w1: " + str(r["w1_chosen"]) if "w1_chosen" in r else "")
            )
        L.append("  (per-class columns: recall = correct / objects of the class, %)")
        L.append("")
        L.append("  Table 3 layout, threshold 0.8 (identified as the class / correct")
        L.append("  / accuracy = correct / identified, per repeat of the 5 folds):")
        for r in res["case_based"]:
            if r["threshold"] != "0.8":
                continue
            L.append(f"  {r['descriptor']}, volume {r['volume']}:")
            for c in classes:
                n = r["n_identified"][c]
                p = r["precision"][c][0]
                L.append(
                    f"      {c:9s} identified {n:6.1f}  correct {n * p:6.1f}  "
                    f"accuracy {100 * p:5.1f}%"
                )

    if "best" in res:
        L += ["", "4. pipelines from the library's pieces", ""]
        for r in sorted(res["best"], key=lambda r: -r["accuracy_mean"]):
            L.append(
                f"  {r['features']:40s} {r['classifier']:6s} "
                f"{_pm(r['accuracy_mean'], r['accuracy_std'])}"
                f"   (fit+predict {r['fit_predict_seconds']:.0f} s over all folds)"
            )
        if "nested" in res:
            n = res["nested"]
            L.append("")
            L.append(
                "  nested CV of 'pick the best of (shape + a histogram) x (RF300, HGB)"
                f" by inner 3-fold CV': {_pm(n['accuracy_mean'], n['accuracy_std'])}"
            )
            L.append(f"  chosen: {n['chosen']}")
        if "timing" in res:
            L.append("")
            L.append("  end to end on the clouds (n_jobs as above):")
            for k, v in res["timing"].items():
                L.append(f"    {k}: {v}")
        base = _find(res["best"], features="shape", classifier="RF300")
        L += [
            "",
            "  default (shape + RF300) per class:",
            *_per_class_lines(base, classes),
        ]
        rec = _find(res["best"], features="shape + improved FPFH", classifier="RF300")
        if rec:
            L += ["  shape + improved FPFH + RF300 per class:"]
            L += _per_class_lines(rec, classes)
    Path(path).write_text("\n".join(L) + "\n")


def _clf_order(c):
    order = ["SVM", "RF100", "RF300", "HGB", "DT", "QDA"]
    return order.index(c) if c in order else 99


def _find(rows, **kw):
    for r in rows:
        if all(r.get(k) == v for k, v in kw.items()):
            return r
    return None


def _per_class_lines(r, classes):
    return [
        "    precision "
        + "  ".join(f"{c} {100 * r['precision'][c][0]:5.1f}" for c in classes),
        "    recall    "
        + "  ".join(f"{c} {100 * r['recall'][c][0]:5.1f}" for c in classes),
    ]


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default=DEFAULT_DATA)
    ap.add_argument("--cache", default=DEFAULT_CACHE)
    ap.add_argument(
        "--quick", action="store_true", help="16 objects per class, 1 repeat"
    )
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--n-jobs", type=int, default=2)
    ap.add_argument(
        "--experiments", default="bof,two_step,case_based,best",
        help="comma-separated subset of bof,two_step,case_based,best,timing",
    )  # fmt: skip
    ap.add_argument("--out", default=None, help="JSON path (.txt written alongside)")
    ap.add_argument(
        "--update",
        action="store_true",
        help="keep the other experiments' results already in --out",
    )
    a = ap.parse_args(argv)
    from threadpoolctl import threadpool_limits

    # One OpenMP/BLAS thread: on a shared, loaded machine two OpenMP threads made
    # HistGradientBoosting 20x slower (spinning threads). ``n_jobs`` goes to the
    # descriptors (numba) and the forests (joblib threads) only.
    threadpool_limits(1)
    todo = a.experiments.split(",")
    out = a.out or str(
        ROOT
        / "results"
        / ("identification_quick.json" if a.quick else "identification.json")
    )
    repeats = 1 if a.quick else a.repeats
    vocab = [15, 30] if a.quick else [15, 30, 50, 100]
    t0 = time.perf_counter()

    from skpcd.features import PFHTransformer

    clouds, y, names = load(a.data, a.quick)
    classes = np.unique(y).tolist()
    folds = splits(y, repeats)
    timings = {}
    log(f"{len(clouds)} objects, {sum(len(c) for c in clouds)} points")
    local = {
        "PFH k=6": cached_local(
            a.cache, names, clouds, "pfh_k6",
            lambda j: PFHTransformer(n_neighbors=6, n_jobs=j), a.n_jobs, timings,
        ),
        "PFH r=0.5 m": cached_local(
            a.cache, names, clouds, "pfh_r05",
            lambda j: PFHTransformer(radius=0.5, n_jobs=j), a.n_jobs, timings,
        ),
    }  # fmt: skip
    seg = cached_segment(a.cache, names, clouds, a.n_jobs, timings)
    log(f"descriptors: {timings}")
    res = {
        "meta": {
            "n_objects": len(clouds),
            "n_points": int(sum(len(c) for c in clouds)),
            "classes": classes,
            "class_counts": {c: int(np.sum(y == c)) for c in classes},
            "cv": f"RepeatedStratifiedKFold, 5 folds x {repeats}, random_state=0",
            "bof_max_descriptors": MAX_DESCRIPTORS,
            "quick": a.quick,
            "n_jobs": a.n_jobs,
            "machine": f"{platform.machine()}, nproc={os.cpu_count()}",
            "descriptor_seconds": {k: round(v, 2) for k, v in timings.items()},
            "undefined_pfh_rows": {
                k: int(sum(np.isnan(d).any(axis=1).sum() for d in v))
                for k, v in local.items()
            },
        }
    }  # fmt: skip

    if a.update and Path(out).is_file():
        old = json.loads(Path(out).read_text())
        res = {**old, "meta": {**old["meta"], **res["meta"]}}

    def save():
        took = round(time.perf_counter() - t0, 1)
        res["meta"]["update_seconds" if a.update else "total_seconds"] = took
        Path(out).parent.mkdir(parents=True, exist_ok=True)
        Path(out).write_text(
            json.dumps({**provenance(), **res}, indent=1, default=_json_default)
        )
        write_text(res, Path(out).with_suffix(".txt"))

    bof_cache = None
    if "case_based" in todo:
        log("experiment 3: case-based")
        res["case_based"] = experiment_case_based(seg, y, folds, repeats)
        save()
    if "best" in todo:
        log("experiment 4: best pipeline")
        res["best"] = experiment_best(
            seg, y, folds, None, None, a.n_jobs, repeats, ["RF300", "HGB", "SVM"]
        )
        save()
        res["nested"] = nested_selection(seg, y, folds, a.n_jobs, repeats)
        save()
        res["timing"] = time_pipelines(clouds, y, folds, a.n_jobs)
        save()
    if "timing" in todo:
        res["timing"] = time_pipelines(clouds, y, folds, a.n_jobs)
        save()
    if "bof" in todo or "two_step" in todo or "best" in todo:
        log("experiment 1: bag of features")
        clfs = ["SVM", "RF100", "DT", "QDA"]
        bof_local = local if "bof" in todo else {"PFH k=6": local["PFH k=6"]}
        voc = vocab if "bof" in todo else [30]
        table, bof_cache = experiment_bof(
            bof_local, y, folds, voc, clfs if "bof" in todo else ["RF100"], a.n_jobs,
            repeats,
        )  # fmt: skip
        if "bof" in todo:
            res["bof"] = table
            save()
    if "best" in todo:
        res["best"] += experiment_best(
            seg, y, folds, bof_cache, ("PFH k=6", 30, "l1"), a.n_jobs, repeats,
            ["RF300", "HGB", "SVM"], only_bof=True,
        )  # fmt: skip
        save()
    if "two_step" in todo:
        log("experiment 2: two-step")
        shape = seg["shape"]
        feats = {
            "BoF(PFH k=6, 30 words, counts)": lambda k, tr, te: bof_cache[
                ("PFH k=6", 30, "counts", k)
            ],
            "shape": lambda k, tr, te: (shape[tr], shape[te]),
        }
        res["two_step"] = experiment_two_step(
            feats, y, folds, a.n_jobs, repeats, 16 if not a.quick else 6,
            ["SVM", "RF100"],
        )  # fmt: skip
        save()
    save()
    log(f"done in {time.perf_counter() - t0:.0f} s: {out}")


if __name__ == "__main__":
    main()
