"""``skpcd fit FOLDER -o MODEL`` and ``skpcd predict MODEL FOLDER -o CSV``."""

import csv
import time

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


def add_parsers(sub):
    fit = sub.add_parser(
        "fit",
        help="fit an identification pipeline (the default one unless --pipeline) "
        "and save it",
        description="Fit the default pipeline on labelled segments and save it "
        "(skops format, with a checksum and the skpcd and scikit-learn versions; "
        "loading it runs no code from the file).",
    )
    fit.add_argument("folder", help="folder of per-segment files")
    add_pipeline_option(fit)
    fit.add_argument(
        "--labels", help="CSV of file,label rows (default: FOLDER/labels.csv)"
    )
    fit.add_argument("-o", "--output", required=True, help="model file (.skpcd)")
    fit.add_argument("--random-state", type=int, default=0, help="seed (default 0)")
    add_n_jobs(fit)
    add_skip_unreadable(fit)
    add_output_options(fit)
    add_scheduler(fit)
    fit.set_defaults(func=run_fit)

    pred = sub.add_parser(
        "predict",
        help="label segments with a saved model",
        description="Predict the class of every segment of a folder; the CSV has "
        "file, label and the probability (or, for a case-based model, the "
        "similarity) of each answer.",
    )
    pred.add_argument("model", help="a model written by skpcd fit")
    pred.add_argument("folder", help="folder of per-segment files")
    pred.add_argument("-o", "--output", required=True, help="predictions CSV")
    add_skip_unreadable(pred)
    add_output_options(pred)
    add_scheduler(pred)
    add_trust_pickle(pred)
    pred.set_defaults(func=run_predict)
    return fit, pred


def run_fit(args):
    from skpcd.classification import PIPELINES, make_named_pipeline
    from skpcd.io import save_model

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
    start = time.perf_counter()
    model.fit(clouds, y)
    print(f"fit       {time.perf_counter() - start:.1f} s")
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


def run_predict(args):
    from skpcd.io._atomic import atomic_path

    out = check_output(args.output, args, "predict", inputs=[args.model])
    check_folder(args.folder, "predict")
    model = load_model_for(args, "predict")
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
