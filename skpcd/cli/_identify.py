"""``skpcd identify``: segment a scene as ``skpcd segment`` does, predict the
class of each segment and write the scene back with the class of every
point, and the legend of its codes beside it. Several scenes, or a folder
of them, stream through one loaded model: :mod:`skpcd.cli._sweeps`."""

import csv
from contextlib import ExitStack

import numpy as np

from skpcd.cli._common import (
    CommandError,
    add_trust_pickle,
    check_output,
    load_model_for,
    predict_or_explain,
    side_file,
    unique_counts,
)
from skpcd.cli._inventory import (
    add_inventory_option,
    check_inventory,
    measuring,
    write_inventory_of,
)
from skpcd.cli._segment import (
    check_method,
    is_las,
    segment_clouds,
    segment_file,
)
from skpcd.cli._segmentation_options import add_segmentation_options


def add_parser(sub):
    ident = sub.add_parser(
        "identify",
        help="segment a scene and label each segment (the shipped street model "
        "unless --model)",
        description="Segment a scene as 'skpcd segment' does, predict the class "
        "of each segment with a model written by 'skpcd fit', or with the "
        "street model shipped with skpcd when no --model is given (facade and wire "
        "segments are classed facade and wire, not predicted), and write the "
        "scene with per-point fields segment (-1: none), class, ground and the "
        "probability or similarity of the answer. A LAS/LAZ scene written as "
        "LAS/LAZ keeps every point and dimension; ground points get "
        "classification 2, class is 64 + the class index (0: none) and the "
        "class names are stored in the file; in other formats class is the "
        "index (-1: none). Class names also go to OUTPUT.classes.csv. "
        "Several scenes, or a folder (its point-cloud files, by name), are "
        "identified one after the other with the model loaded once (sweeps "
        "of a spinning sensor: --method range-image, tens of ms a sweep): "
        "-o is then a folder, created if missing, which gets each scene "
        "under its own file name (same format, a LAS/LAZ with every "
        "dimension) and its .classes.csv; no output may replace an input, "
        "the folder may not be an input's, nor two scenes share a name, and "
        "without --overwrite no output may exist (all checked before the "
        "first scene). An interrupt, or a scene that cannot be read "
        "(stopping there with an error naming it), leaves the scenes done "
        "before written whole and nothing of the one under way.",
    )
    ident.add_argument(
        "scene",
        nargs="+",
        metavar="SCENE",
        help="a point-cloud file; or several, or a folder of them (then -o "
        "names a folder)",
    )
    ident.add_argument(
        "--model",
        help="a model written by skpcd fit (default: the shipped street model, "
        "fitted on simulated streets)",
    )
    ident.add_argument(
        "-o",
        "--output",
        required=True,
        help="labelled scene (.las .laz .ply .pcd...); with several scenes or "
        "a folder, the output folder",
    )
    add_inventory_option(ident)
    ident.add_argument(
        "--classes-into",
        choices=("classification", "extra"),
        default="classification",
        help="LAS/LAZ output: write the classes into classification (ASPRS "
        "codes where they exist: building 6, tree 5, wire 14...; user codes 64+ "
        "otherwise; the input's classification kept in original_classification; "
        "what viewers colour by) or leave classification as it was, ground "
        "aside (default classification)",
    )
    add_segmentation_options(ident)
    add_trust_pickle(ident)
    ident.set_defaults(func=run_identify)
    return ident


def write_legend(path, classes, seg_class, seg_sizes, n_points, *, las, into):
    """identify's ``OUTPUT.classes.csv``: a row per class with its index
    (the ``class`` field of a PLY, PCD or text output), the code of the
    ``class`` extra dimension of a LAS/LAZ output (64 + index), the code its
    ``classification`` holds (ASPRS or user code; blank when the output
    has no classification of classes), the name, the segments and points."""
    from skpcd.io._class_codes import classification_codes

    names = [str(c) for c in classes]
    in_classification = las and into == "classification"
    codes = classification_codes(names) if in_classification else [""] * len(names)
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(
            ["class", "class_code", "classification", "name", "n_segments", "n_points"]
        )
        outside = n_points - int(seg_sizes.sum())
        writer.writerow(
            [-1, 0, 1 if in_classification else "", "(no segment)", 0, outside]
        )
        for j, name in enumerate(names):
            mine = seg_class == j
            writer.writerow(
                [j, 64 + j, codes[j], name, int(mine.sum()), int(seg_sizes[mine].sum())]
            )


def run_identify(args):
    from skpcd.cli._sweeps import is_several, run_sweeps

    check_method(args, "identify")
    if isinstance(args.scene, str):  # one scene, as a caller may give it
        args.scene = [args.scene]
    if is_several(args.scene):
        return run_sweeps(args)
    args.scene = args.scene[0]
    inputs = [args.scene] + ([args.model] if args.model else [])
    out = check_output(args.output, args, "identify", inputs=inputs)
    legend = check_output(
        side_file(out, "classes.csv"), args, "identify", inputs=inputs
    )
    inventory = check_inventory(args, "identify", inputs)
    model = load_model_for(args, "identify")
    pred, kind, _ = identify_scene(args, model, out, legend, inventory)
    if not args.quiet:
        print(f"classes   {unique_counts(pred) or 'none'}")
        print(
            f"written   {out} (fields segment, class, ground"
            + (f", {kind}" if kind else "")
            + f"); class names in {legend.name}"
        )
    return 0


def identify_scene(args, model, out, legend, inventory=None):
    """Segment ``args.scene``, classify its segments with ``model`` and
    write the labelled scene to ``out``, the legend to ``legend`` (and the
    inventory), each atomically; returns ``(pred, kind, result)``: the
    class of each segment, the name of the score field (or None) and the
    segmentation."""
    from skpcd.classification import identify_segments
    from skpcd.io import write_labelled_scan
    from skpcd.io._atomic import atomic_path, scratch_folder
    from skpcd.segmentation._members import spread_to_points
    from skpcd.utils._progress import stage

    geometries = []
    points, _, result = segment_file(args, "identify")
    n_points = len(result.labels)
    with ExitStack() as stack:
        work = stack.enter_context(scratch_folder(out.parent))
        segments = segment_clouds(args, points, {}, result, work, fields=False)
        if inventory is not None:  # measured only for the inventory
            segments = measuring(segments, geometries)
        pred, kind, seg_score, seg_sizes = identify_segments(
            model,
            segments,
            kinds=result.kinds,
            predict=lambda m, clouds: predict_or_explain(m, clouds, args, "identify"),
        )
        classes = list(getattr(model, "classes_", []))
        classes += sorted({str(p) for p in pred} - {str(c) for c in classes})
        index = {str(c): j for j, c in enumerate(classes)}
        seg_class = np.array([index[str(p)] for p in pred], dtype=np.int32)

        def per_point(name, values, fill, dtype):
            target = (
                np.empty(n_points, dtype=dtype)
                if points is not None
                else np.lib.format.open_memmap(
                    work / f"{name}.npy", "w+", dtype=dtype, shape=(n_points,)
                )
            )
            return spread_to_points(result.labels, values, fill, target)

        point_class = per_point("class", seg_class, -1, np.int32)
        point_score = (
            per_point("score", seg_score.astype(np.float32), np.nan, np.float32)
            if kind
            else None
        )
        out_tmp = stack.enter_context(atomic_path(out, overwrite=args.overwrite))
        legend_tmp = stack.enter_context(atomic_path(legend, overwrite=args.overwrite))
        stack.enter_context(stage(f"writing {out.name}"))
        try:
            write_labelled_scan(
                args.scene,
                out_tmp,
                segment=result.labels,
                class_index=point_class,
                class_names=[str(c) for c in classes],
                score=point_score,
                score_name=kind,
                ground=result.ground,
                # a LAS/LAZ copy always keeps every dimension of the scan
                keep_fields=args.keep_fields or (is_las(args.scene) and is_las(out)),
                classes_into=args.classes_into,
            )
        except ValueError as exc:  # a field the format cannot hold, ...
            raise CommandError("identify", str(exc)) from exc
        write_legend(
            legend_tmp, classes, seg_class, seg_sizes, n_points,
            las=is_las(out), into=args.classes_into,
        )  # fmt: skip
        if inventory is not None:
            write_inventory_of(
                args, inventory, geometries, pred, seg_score, points, result
            )
    return pred, kind, result
