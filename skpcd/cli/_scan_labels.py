"""Scans labelled point by point: their options (``skpcd fit SCANS
--labels-from FIELD``) and ``skpcd score-scan PRED --truth TRUTH``."""

import csv
import json
import time
from pathlib import Path

from skpcd.cli._common import CommandError, add_output_options, check_output

MAP_HELP = (
    "CSV of code,name rows: a class code (or a class name) and the class it "
    "becomes, 'ignore' to leave its points out; or 'semantickitti' (raw "
    "SemanticKITTI ids to its class names, moving classes folded, unlabeled "
    "and outlier ignored)"
)


def add_scan_label_options(parser):
    """``--labels-from``, ``--instances-from`` and ``--class-map``."""
    parser.add_argument(
        "--labels-from",
        metavar="FIELD",
        help="labelled scans: the field holding each point's class (default "
        "classification; a KITTI .bin scan's labels are its .label file)",
    )
    parser.add_argument(
        "--instances-from",
        metavar="FIELD",
        help="labelled scans: the field holding object ids, 'none' for none "
        "(default: SemanticKITTI's instance bits, or a field named instance or "
        "object_id); objects with an id are cut by it, the rest by skpcd's "
        "segmentation",
    )
    parser.add_argument("--class-map", metavar="MAP", help=MAP_HELP)


def instances_option(value):
    """``read_point_labels``'s ``instances`` from ``--instances-from``."""
    if value is None:
        return "auto"
    return None if value.lower() == "none" else value


def add_parser(sub):
    p = sub.add_parser(
        "score-scan",
        help="per-point scores of labelled scans: IoU, precision, recall per "
        "class, mIoU, accuracy, confusion matrix",
        description="Score the classes skpcd identify (or another tool) gave "
        "the points of one or more scans against their true classes: a field "
        "of the same file, or another file with the same points in the same "
        "order. Prints per-class IoU, precision and recall, mIoU and overall "
        "accuracy, and the confusion matrix in counts and shares, pooled over "
        "the scans, and the mIoU of each scan.",
    )
    p.add_argument(
        "predictions",
        nargs="+",
        metavar="PRED",
        help="a scan labelled by skpcd identify (its class and ground fields), "
        "or by another tool with --pred-from",
    )
    p.add_argument(
        "--truth",
        nargs="+",
        required=True,
        metavar="TRUTH",
        help="a field of each PRED holding the true classes (identify keeps the "
        "scan's own fields; the scan's classification is kept as "
        "original_classification), or one file per PRED with the same points",
    )
    p.add_argument(
        "--truth-from",
        metavar="FIELD",
        help="with TRUTH files, their field of the true classes (default "
        "classification; a KITTI .bin scan's .label)",
    )
    p.add_argument(
        "--pred-from",
        metavar="FIELD",
        help="the field of the predicted classes (default: what skpcd identify wrote)",
    )
    p.add_argument(
        "--map",
        metavar="MAP",
        help=MAP_HELP + "; applied to the truth and, by name, to the predictions, "
        "so that one map folds both onto the classes scored",
    )
    p.add_argument(
        "--classes",
        metavar="NAMES",
        help="comma-separated classes to score and average (default: every true "
        "class with points)",
    )
    p.add_argument(
        "-o",
        "--output",
        help="also write the scores: .json (everything, per scan and pooled), "
        ".csv (a row per scan and class), any other name the report as printed",
    )
    add_output_options(p)
    p.set_defaults(func=run_score_scan)
    return p


def _truth_files(args):
    """One truth file per PRED, or None when TRUTH names a field."""
    from skpcd.io._api import SUPPORTED_EXTENSIONS

    truth = args.truth
    as_field = (
        len(truth) == 1
        and not Path(truth[0]).exists()
        and Path(truth[0]).suffix.lower() not in SUPPORTED_EXTENSIONS
    )
    if as_field:
        if args.truth_from is not None:
            raise CommandError(
                "score-scan", "--truth-from applies to TRUTH files, not a field"
            )
        return None
    if len(truth) != len(args.predictions):
        raise CommandError(
            "score-scan",
            f"{len(args.predictions)} PRED but {len(truth)} TRUTH files: give one "
            "truth file per prediction, or the name of a field",
        )
    return [Path(t) for t in truth]


def _read_pair(pred_path, truth_path, args, class_map):
    """The predicted and true classes of one scan, checked to match."""
    from skpcd.exceptions import PointCloudFileError
    from skpcd.io import read_point_labels, read_predicted_labels

    pred = read_predicted_labels(pred_path, args.pred_from, class_map=class_map)
    field = args.truth_from if truth_path is not None else args.truth[0]
    source = truth_path if truth_path is not None else pred_path
    truth = read_point_labels(
        source, field, instances=None, class_map=class_map, nonfinite="keep"
    ).labels
    if len(truth) != len(pred):
        raise PointCloudFileError(
            source,
            f"holds {len(truth)} points but the prediction {pred_path} holds "
            f"{len(pred)}: not the same scan",
        )
    return truth, pred


def run_score_scan(args):
    import numpy as np

    from skpcd.io import read_class_map
    from skpcd.metrics import format_scan_scores, scan_scores

    truths = _truth_files(args)
    inputs = [*args.predictions, *(truths or [])]
    out = None
    if args.output is not None:
        out = check_output(args.output, args, "score-scan", inputs=inputs)
    class_map = read_class_map(args.map) if args.map else None
    classes = [c.strip() for c in args.classes.split(",")] if args.classes else None
    start = time.perf_counter()
    per_scan, all_truth, all_pred = [], [], []
    for i, pred_path in enumerate(args.predictions):
        truth_path = None if truths is None else truths[i]
        truth, pred = _read_pair(pred_path, truth_path, args, class_map)
        all_truth.append(truth)
        all_pred.append(pred)
        _warn_if_disjoint(truth, pred, pred_path)
        try:
            scores = scan_scores(truth, pred, classes=_present(classes, truth))
        except ValueError as exc:
            raise CommandError("score-scan", f"{pred_path}: {exc}") from exc
        per_scan.append((pred_path, truth_path, scores))
    try:
        pooled = scan_scores(
            np.concatenate(all_truth), np.concatenate(all_pred), classes=classes
        )
    except ValueError as exc:
        raise CommandError("score-scan", str(exc)) from exc
    report = format_scan_scores(pooled)
    if len(per_scan) > 1:
        width = max(len(str(p)) for p, _, _ in per_scan)
        lines = [f"{'scan':<{width}} {'points':>9} {'mIoU':>7} {'accuracy':>8}"]
        for path, _, s in per_scan:
            lines.append(
                f"{path!s:<{width}} {s.n_points:>9d} {s.miou:7.4f} {s.accuracy:8.4f}"
            )
        report = "\n".join(lines) + "\n\npooled over the scans\n" + report
    if not args.quiet:
        print(f"scored    {len(per_scan)} scans ({time.perf_counter() - start:.1f} s)")
        print()
        print(report)
    if out is not None:
        _write_report(out, args, report, per_scan, pooled)
        if not args.quiet:
            print(f"\nwritten   {out}")
    return 0


def _warn_if_disjoint(truth, pred, path):
    """One line when no true class is a predicted one: the names of the two
    sides differ (codes against names), which a --map reconciles."""
    import warnings

    import numpy as np

    def listed(names):
        names = sorted(names)
        return ", ".join(names[:6]) + (", ..." if len(names) > 6 else "")

    true, predicted = set(np.unique(truth)) - {"ignore"}, set(np.unique(pred))
    if true and not true & predicted:
        warnings.warn(
            f"{path}: no true class ({listed(true)}) is a predicted class "
            f"({listed(predicted)}): every IoU is 0; name both sides alike "
            "with --map",
            UserWarning,
            stacklevel=2,
        )


def _present(classes, truth):
    """The classes asked for that this scan's truth holds (a scan need not
    hold every class of the pool); None: every true class."""
    if classes is None:
        return None
    import numpy as np

    held = set(np.unique(truth).tolist())
    return [c for c in classes if c in held] or None


def _numbers(scores):
    """The scores of one scan as JSON-ready values."""
    return {
        "n_points": scores.n_points,
        "n_ignored": scores.n_ignored,
        "miou": scores.miou,
        "accuracy": scores.accuracy,
        "classes": scores.classes,
        "predicted": scores.predicted,
        "iou": scores.iou,
        "precision": scores.precision,
        "recall": scores.recall,
        "support": scores.support,
        "confusion": scores.confusion.tolist(),
        "confusion_normalized": scores.confusion_normalized.tolist(),
    }


def _write_report(out, args, report, per_scan, pooled):
    """By the extension of ``out``: JSON, a CSV row per scan and class, or
    the report as printed; written whole or not at all."""
    from skpcd.io._atomic import atomic_path

    suffix = out.suffix.lower()
    with atomic_path(out, overwrite=args.overwrite) as tmp:
        with open(tmp, "w", newline="") as f:
            if suffix == ".json":
                json.dump(
                    {
                        "scans": [
                            {
                                "prediction": str(p),
                                "truth": str(t if t is not None else args.truth[0]),
                                **_numbers(s),
                            }
                            for p, t, s in per_scan
                        ],
                        "pooled": _numbers(pooled),
                        "map": args.map,
                    },
                    f,
                    indent=1,
                )
                f.write("\n")
            elif suffix == ".csv":
                writer = csv.writer(f)
                writer.writerow(
                    ["scan", "class", "iou", "precision", "recall", "points"]
                )
                for name, s in [(str(p), s) for p, _, s in per_scan] + [
                    ("(pooled)", pooled)
                ]:
                    for c in s.classes:
                        writer.writerow(
                            [
                                name,
                                c,
                                f"{s.iou[c]:.6f}",
                                f"{s.precision[c]:.6f}",
                                f"{s.recall[c]:.6f}",
                                s.support[c],
                            ]
                        )
                    writer.writerow([name, "(mean)", f"{s.miou:.6f}", "", "", ""])
            else:
                f.write(report + "\n")
