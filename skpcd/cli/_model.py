"""``skpcd fit FOLDER -o MODEL`` and ``skpcd predict MODEL FOLDER -o CSV``."""

import csv
import time
from pathlib import Path

import numpy as np

from skpcd.cli._common import (
    CommandError,
    add_n_jobs,
    add_output_options,
    add_scheduler,
    add_skip_unreadable,
    add_trust_pickle,
    check_folder,
    check_not_an_input,
    check_output,
    labels_path,
    load_labelled,
    load_model_for,
    predict_or_explain,
    read_folder,
    unique_counts,
)
from skpcd.cli._evaluate import add_pipeline_option
from skpcd.cli._scan_labels import add_scan_label_options, instances_option
from skpcd.exceptions import PointCloudFileError


def add_parsers(sub):
    fit = sub.add_parser(
        "fit",
        help="fit an identification pipeline (the default one unless --pipeline) "
        "and save it",
        description="Fit the default pipeline on labelled segments, or on objects "
        "cut from scans labelled point by point, and save it "
        "(skops format, with a checksum and the skpcd and scikit-learn versions; "
        "loading it runs no code from the file).",
    )
    fit.add_argument(
        "paths",
        nargs="+",
        metavar="PATH",
        help="a folder of per-segment files (labels in labels.csv or --labels), "
        "or scans labelled point by point: LAS/LAZ, PLY, PCD, text or KITTI .bin "
        "files, and folders of them (SemanticKITTI's sequences/NN layout too)",
    )
    add_pipeline_option(fit)
    fit.add_argument(
        "--labels", help="CSV of file,label rows (default: FOLDER/labels.csv)"
    )
    add_scan_label_options(fit)
    fit.add_argument(
        "--min-purity",
        type=float,
        default=0.5,
        help="labelled scans: the least share of its majority class a segment "
        "needs to be kept (default 0.5)",
    )
    fit.add_argument("-o", "--output", required=True, help="model file (.skpcd)")
    fit.add_argument("--random-state", type=int, default=0, help="seed (default 0)")
    fit.add_argument(
        "--simulate",
        type=int,
        metavar="N",
        help="add N simulated objects of every labelled class the street simulator "
        "knows (car, person, pole, tree, traffic_sign...) to the real ones "
        "(SimulationAugmented): for a handful of real labels",
    )
    fit.add_argument(
        "--scanner",
        choices=["auto", "spinning", "mobile", "ugv"],
        default="auto",
        help="scan pattern of the simulated objects with --simulate (default auto: "
        "the one whose objects label your segments best)",
    )
    fit.add_argument(
        "--real-weight",
        type=float,
        default=None,
        help="weight of a real segment against a simulated one with --simulate "
        "(default: SimulationAugmented's)",
    )
    add_n_jobs(fit)
    add_skip_unreadable(fit)
    add_output_options(fit)
    add_scheduler(fit)
    fit.set_defaults(func=run_fit)

    pred = sub.add_parser(
        "predict",
        help="label segments with a saved model (the shipped street model when "
        "none is given)",
        description="Predict the class of every segment of a folder with a model "
        "written by skpcd fit, or with the street model shipped with skpcd when "
        "none is given; the CSV has "
        "file, label and the probability (or, for a case-based model, the "
        "similarity) of each answer.",
    )
    pred.add_argument(
        "paths",
        nargs="+",
        metavar="PATH",
        help="[MODEL] FOLDER: a model written by skpcd fit (default: the shipped "
        "street model, fitted on simulated streets), then the folder of "
        "per-segment files",
    )
    pred.add_argument(
        "--model", dest="model_option", metavar="MODEL", help="the model, as an option"
    )
    pred.add_argument("-o", "--output", required=True, help="predictions CSV")
    add_n_jobs(pred)
    add_skip_unreadable(pred)
    add_output_options(pred)
    add_scheduler(pred)
    add_trust_pickle(pred)
    pred.set_defaults(func=run_predict)
    return fit, pred


def _from_scans(args):
    """Whether ``skpcd fit`` reads scans labelled point by point (not one
    folder of segments)."""
    for path in args.paths:
        check_folder(path, "fit")  # a misspelled name: "does not exist"
    given = args.labels_from or args.instances_from or args.class_map
    single = len(args.paths) == 1 and Path(args.paths[0]).is_dir()
    if given or not single:
        if args.labels is not None:
            raise CommandError(
                "fit",
                "--labels names the labels of a folder of segments; scans "
                "labelled point by point take --labels-from FIELD",
            )
        return True
    args.folder = args.paths[0]
    return False


def _labelled_objects(args):
    """The objects cut from labelled scans: ``(clouds, y, source, inputs)``."""
    from skpcd.datasets import objects_from_labelled_scans
    from skpcd.io import labelled_scan_paths
    from skpcd.utils._progress import stage

    scans = labelled_scan_paths(args.paths)
    with stage(f"cutting objects from {len(scans)} labelled scans"):
        try:
            found = objects_from_labelled_scans(
                scans,
                args.labels_from,
                instances=instances_option(args.instances_from),
                class_map=args.class_map,
                min_purity=args.min_purity,
                n_jobs=args.n_jobs,
            )
        except ValueError as exc:
            if isinstance(exc, PointCloudFileError):
                raise
            raise CommandError("fit", str(exc)) from exc
    cuts = ", ".join(
        f"{int((found.cut == c).sum())} by {c}" for c in ("instance", "segment")
    )
    print(
        f"objects   {len(found.clouds)} from {len(scans)} scans ({cuts}), "
        f"purity median {np.median(found.purity):.2f}; left out "
        + ", ".join(f"{n} {why}" for why, n in found.left_out.items())
    )
    source = f"{len(scans)} labelled scans"
    return found.clouds, np.asarray(found.labels).astype(str), source, scans


def run_fit(args):
    from skpcd.classification import PIPELINES, make_named_pipeline
    from skpcd.io import save_model
    from skpcd.utils._progress import stage

    if not 0 <= args.min_purity <= 1:
        raise CommandError(
            "fit", f"--min-purity must be within 0 and 1, got {args.min_purity}"
        )
    if _from_scans(args):
        out = check_output(args.output, args, "fit", inputs=args.paths)
        clouds, y, source, inputs = _labelled_objects(args)
    else:
        out = check_output(args.output, args, "fit", inputs=[labels_path(args)])
        clouds, y, source, inputs = load_labelled(args)
    check_not_an_input(out, "fit", inputs)
    classes, counts = np.unique(y, return_counts=True)
    if len(classes) < 2 and args.pipeline == "default":
        raise CommandError(
            "fit",
            f"every segment is labelled {str(classes[0])!r}, so the default "
            "pipeline would give that label to everything; label at least 2 "
            "classes (--pipeline case-based accepts one: that class or unknown)",
        )
    print(f"data      {source}: {len(clouds)} segments, {len(classes)} classes")
    model = make_named_pipeline(
        args.pipeline, random_state=args.random_state, n_jobs=args.n_jobs
    )
    if args.simulate is not None:
        model = _augmented(model, args)
    start = time.perf_counter()
    with stage("fitting"):  # its elapsed time, on a terminal
        model.fit(clouds, y)
    print(f"fit       {time.perf_counter() - start:.1f} s")
    if args.simulate is not None:
        print(
            f"simulated {model.n_simulated_} objects of "
            f"{', '.join(model.simulated_classes_) or 'no class'}"
            + (f" ({model.scanner_} pattern)" if model.scanner_ else "")
        )
    metadata = {
        "data": source,
        "n_segments": len(clouds),
        "classes": {str(c): int(n) for c, n in zip(classes, counts)},
        "pipeline": f"{args.pipeline}: {PIPELINES[args.pipeline]}",
        "estimator": repr(model),
    }
    save_model(model, out, metadata=metadata, overwrite=args.overwrite)
    print(f"model     {out}")
    return 0


def _model_and_folder(args):
    """``[MODEL] FOLDER`` or ``--model MODEL FOLDER`` into args.model, args.folder."""
    paths = args.paths
    if len(paths) > 2 or (len(paths) == 2 and args.model_option):
        raise CommandError(
            "predict",
            f"expected [MODEL] FOLDER, got {len(paths)} paths"
            + (" and --model" if args.model_option else ""),
        )
    args.folder = paths[-1]
    args.model = paths[0] if len(paths) == 2 else args.model_option


def _augmented(pipeline, args):
    """The pipeline inside SimulationAugmented, as ``--simulate`` asks."""
    from skpcd.classification import SimulationAugmented

    if args.simulate < 1:
        raise CommandError("fit", f"--simulate must be at least 1, got {args.simulate}")
    kw = {} if args.real_weight is None else {"real_weight": args.real_weight}
    if args.real_weight is not None and not args.real_weight > 0:
        raise CommandError(
            "fit", f"--real-weight must be positive, got {args.real_weight}"
        )
    return SimulationAugmented(
        pipeline,
        n_per_class=args.simulate,
        scanner=args.scanner,
        random_state=args.random_state,
        n_jobs=args.n_jobs,
        **kw,
    )


def with_n_jobs(model, n_jobs):
    """``model`` with the ``n_jobs`` of every part set to ``n_jobs``: its
    parameters (pipeline steps, feature unions, wrapped estimators) and its
    fitted parts (``estimator_`` of a wrapper, the trees of a forest...),
    which predict with them. The answers do not depend on it.

    Parameters
    ----------
    model : estimator
        A fitted model (as :func:`~skpcd.io.load_model` returns it).
    n_jobs : int
        Threads (-1: all cores).

    Returns
    -------
    model : estimator
        The same object, changed in place.
    """
    seen = set()

    def visit(est):
        if id(est) in seen or not hasattr(est, "get_params"):
            return
        seen.add(id(est))
        params = est.get_params(deep=True)
        names = [k for k in params if k == "n_jobs" or k.endswith("__n_jobs")]
        if names:
            est.set_params(**dict.fromkeys(names, n_jobs))
        parts = [v for k, v in params.items() if "__" not in k]
        parts += [v for k, v in vars(est).items() if k.endswith("_")]
        for part in parts:
            for item in part if isinstance(part, (list, tuple)) else [part]:
                visit(item[-1] if isinstance(item, tuple) else item)

    visit(model)
    return model


def run_predict(args):
    from skpcd.io._atomic import atomic_path

    _model_and_folder(args)
    out = check_output(
        args.output, args, "predict", inputs=[args.model] if args.model else []
    )
    check_folder(args.folder, "predict")
    model = with_n_jobs(load_model_for(args, "predict"), args.n_jobs)
    clouds, _, names, files = read_folder(args)
    check_not_an_input(out, "predict", files)
    pred, kind, score = predict_or_explain(model, clouds, args, "predict")
    with atomic_path(out, overwrite=args.overwrite) as tmp:
        with open(tmp, "w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(["file", "label"] + ([kind] if kind else []))
            for i, name in enumerate(names):
                writer.writerow([name, pred[i]] + ([f"{score[i]:.6f}"] if kind else []))
    print(f"predicted {len(names)} segments ({unique_counts(pred)}) -> {out}")
    return 0
