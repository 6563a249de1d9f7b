"""``skpcd review FOLDER [--model MODEL] -o review.html``."""

import csv
import sys
from pathlib import Path

from skpcd.cli._common import (
    CommandError,
    add_output_options,
    add_skip_unreadable,
    add_trust_pickle,
    check_folder,
    check_output,
    load_model_for,
    predict_or_explain,
    read_folder,
)


def add_parser(sub):
    p = sub.add_parser(
        "review",
        help="write an HTML page to look at segments and label them",
        description="Write one self-contained HTML file (no server, no network: "
        "open it in a browser from disk) with a card per segment of FOLDER: a top "
        "and a side view coloured by height, its size, and the class predicted by "
        "the model with its confidence, least confident first, filterable by "
        "class. Label the segments with the keyboard (number keys: classes; a: "
        "accept the prediction; j/k or arrows: move) and save a labels.csv that "
        "'skpcd fit FOLDER' reads as it is. The labels of FOLDER/labels.csv (or "
        "--labels) are shown and kept.",
    )
    p.add_argument("folder", help="folder of per-segment files (skpcd segment's)")
    p.add_argument(
        "--model",
        help="a model written by skpcd fit (default: the shipped street model)",
    )
    p.add_argument(
        "--no-model",
        action="store_true",
        help="predict nothing: cards in file order, no predicted class",
    )
    p.add_argument(
        "--labels",
        help="CSV of file,label rows already given (default: FOLDER/labels.csv "
        "if present); may label only some segments",
    )
    p.add_argument("-o", "--output", required=True, help="the HTML page (.html)")
    p.add_argument(
        "--thumbnail-size",
        type=int,
        default=96,
        help="width and height of each view in pixels (default 96)",
    )
    add_skip_unreadable(p)
    add_trust_pickle(p)
    add_output_options(p)
    p.set_defaults(func=run_review)
    return p


def _existing_labels(args, names):
    """The labels already given, for the segments of the folder only."""
    from skpcd.io._segment_folder import read_labels

    path = args.labels
    if path is None:
        default = Path(args.folder) / "labels.csv"
        if not default.is_file():
            return None, {}
        path = default
    path, mapping = read_labels(path)
    unknown = sorted(set(mapping) - set(names))
    if unknown:
        print(
            f"skpcd review: warning: {path}: {len(unknown)} labelled file(s) are "
            f"not in {args.folder} and are left out: {', '.join(unknown[:5])}",
            file=sys.stderr,
        )
    return path, {n: mapping[n] for n in names if n in mapping}


def _kinds(folder, names):
    """The type of each segment (object, facade, wire) from segments.csv,
    or None without one."""
    from skpcd.io._segment_folder import SEGMENTS_SUMMARY

    summary = Path(folder) / SEGMENTS_SUMMARY
    if not summary.is_file():
        return None
    with open(summary, newline="", encoding="utf-8") as fh:
        types = {row["file"]: row.get("type") or "object" for row in csv.DictReader(fh)}
    return [types.get(n, "object") for n in names]


def run_review(args):
    from skpcd.classification import identify_segments
    from skpcd.io._review import write_review_page

    check_folder(args.folder, "review")
    if args.no_model and args.model:
        raise CommandError("review", "--model and --no-model cannot go together")
    if args.thumbnail_size < 16 or args.thumbnail_size > 512:
        raise CommandError(
            "review", f"--thumbnail-size must be 16 to 512, got {args.thumbnail_size}"
        )
    out = check_output(args.output, args, "review", inputs=[args.labels, args.model])
    model = None if args.no_model else load_model_for(args, "review")
    clouds, _, names, _ = read_folder(args)
    labels_file, labels = _existing_labels(args, names)
    predictions = scores = kind = None
    classes = None
    if model is not None:
        predictions, kind, scores, _ = identify_segments(
            model,
            ((c, {}) for c in clouds),
            kinds=_kinds(args.folder, names),
            predict=lambda m, c: predict_or_explain(m, c, args, "review"),
        )
        classes = [str(c) for c in getattr(model, "classes_", [])]
    n = write_review_page(
        out,
        clouds,
        names,
        predictions=predictions,
        scores=scores,
        score_kind=kind,
        labels=labels,
        classes=classes,
        title=f"skpcd review: {Path(args.folder).resolve().name}",
        thumbnail_size=args.thumbnail_size,
        overwrite=args.overwrite,
    )
    if not args.quiet:
        given = f", {len(labels)} labels from {labels_file}" if labels else ""
        print(f"written   {out}: {n} segments{given}")
        print(
            f"next      open it in a browser, label, save labels.csv into "
            f"{args.folder}, then: skpcd fit {args.folder} -o model.skpcd"
        )
    return 0
