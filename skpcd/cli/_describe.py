"""``skpcd describe FOLDER -o NPZ``: segment descriptors for your own work."""

import time
from pathlib import Path

import numpy as np

from skpcd.cli._common import (
    CommandError,
    add_n_jobs,
    add_output_options,
    add_scheduler,
    add_skip_unreadable,
    check_not_an_input,
    check_output,
    read_folder,
)

DESCRIPTORS = (
    "shape",
    "overall",
    "improved_pfh",
    "improved_fpfh",
    "pfh_mean",
    "fpfh_mean",
)


def add_parser(sub):
    desc = sub.add_parser(
        "describe",
        help="compute segment descriptors into an .npz file",
        description="Compute descriptors of every segment of a folder and save "
        "them with numpy.savez_compressed: 'names', 'labels' (when labelled), one "
        "(n_segments, n_features) array per descriptor with its '<name>_columns', "
        "and with --local the per-point descriptors packed with offsets.",
    )
    desc.add_argument("folder", help="folder of per-segment files")
    desc.add_argument("-o", "--output", required=True, help="output .npz file")
    desc.add_argument(
        "--labels", help="CSV of file,label rows (default: FOLDER/labels.csv if any)"
    )
    desc.add_argument(
        "--descriptors",
        default="shape,overall,improved_pfh",
        help=f"comma list of {', '.join(DESCRIPTORS)} (default: "
        "shape,overall,improved_pfh)",
    )
    desc.add_argument(
        "--local", choices=("pfh", "fpfh"), help="also store per-point descriptors"
    )
    desc.add_argument(
        "--n-neighbors", type=int, default=10, help="k of the local descriptors"
    )
    add_n_jobs(desc)
    add_skip_unreadable(desc)
    add_output_options(desc)
    add_scheduler(desc)
    desc.set_defaults(func=run)
    return desc


def _descriptor(name, n_neighbors, n_jobs):
    from skpcd.features import (
        FPFHTransformer,
        ImprovedPFHTransformer,
        OverallDescriptor,
        PFHTransformer,
        ShapeFeatures,
    )

    k = {"n_neighbors": n_neighbors, "n_jobs": n_jobs}
    make = {
        "shape": lambda: ShapeFeatures(),
        "overall": lambda: OverallDescriptor(),
        "improved_pfh": lambda: ImprovedPFHTransformer("pfh", **k),
        "improved_fpfh": lambda: ImprovedPFHTransformer("fpfh", **k),
        "pfh_mean": lambda: PFHTransformer(pooling="mean", undefined="drop", **k),
        "fpfh_mean": lambda: FPFHTransformer(pooling="mean", undefined="drop", **k),
    }
    return make[name]()


def run(args):
    from skpcd.features import FPFHTransformer, PFHTransformer
    from skpcd.io._atomic import atomic_path

    wanted = [d.strip() for d in args.descriptors.split(",") if d.strip()]
    if not wanted and not args.local:
        raise CommandError(
            "describe",
            f"no descriptor asked for (--descriptors {args.descriptors!r}); choose "
            f"from {', '.join(DESCRIPTORS)}",
        )
    unknown = sorted(set(wanted) - set(DESCRIPTORS))
    if unknown:
        raise CommandError(
            "describe",
            f"unknown descriptor(s) {', '.join(unknown)}; choose from "
            f"{', '.join(DESCRIPTORS)}",
        )
    labels = args.labels
    if labels is None and (Path(args.folder) / "labels.csv").is_file():
        labels = Path(args.folder) / "labels.csv"
    out = check_output(args.output, args, "describe", inputs=[labels])
    clouds, y, names, files = read_folder(args, labels)
    check_not_an_input(out, "describe", files)
    arrays = {"names": np.asarray(names)}
    if y is not None:
        arrays["labels"] = np.asarray(y)
    for name in wanted:
        start = time.perf_counter()
        est = _descriptor(name, args.n_neighbors, args.n_jobs)
        try:
            arrays[name] = np.asarray(est.fit_transform(clouds), dtype=np.float64)
        except ValueError as exc:  # e.g. --n-neighbors out of range
            raise CommandError("describe", f"{name}: {exc}") from exc
        arrays[f"{name}_columns"] = np.asarray(est.get_feature_names_out(), dtype=str)
        print(f"{name:<14}{arrays[name].shape}  {time.perf_counter() - start:.1f} s")
    if args.local:
        cls = {"pfh": PFHTransformer, "fpfh": FPFHTransformer}[args.local]
        start = time.perf_counter()
        try:
            est = cls(n_neighbors=args.n_neighbors, n_jobs=args.n_jobs)
            rows = est.fit_transform(clouds)
        except ValueError as exc:
            raise CommandError("describe", f"{args.local}: {exc}") from exc
        arrays[args.local] = np.vstack(rows)
        arrays[f"{args.local}_offsets"] = np.cumsum([0] + [len(r) for r in rows])
        print(
            f"{args.local:<14}{arrays[args.local].shape} per point (rows of segment "
            f"i: {args.local}_offsets[i]:{args.local}_offsets[i + 1])  "
            f"{time.perf_counter() - start:.1f} s"
        )
    with atomic_path(out, overwrite=args.overwrite) as tmp, open(tmp, "wb") as f:
        np.savez_compressed(f, **arrays)
    print(f"written   {out}")
    return 0
