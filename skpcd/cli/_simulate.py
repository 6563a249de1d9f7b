"""``skpcd simulate -o FOLDER``: simulated labelled objects written as the
folder that ``skpcd fit`` reads (one file per object and ``labels.csv``)."""

import csv
import re
from pathlib import Path

from skpcd.cli._common import CommandError, add_n_jobs, add_output_options
from skpcd.cli._evaluate import DATA, simulated_data
from skpcd.cli._segment import SEGMENT_FORMATS

LABELS = "labels.csv"
# the files of a simulated folder: object_0000.ply ... and labels.csv
_OBJECT_FILE = re.compile(rf"object_\d{{4,}}\.({'|'.join(SEGMENT_FORMATS)})")


def is_simulated_file(name):
    """Whether ``name`` is an entry that ``skpcd simulate`` writes (an
    object file or the labels); ``--overwrite`` replaces only those."""
    return name == LABELS or bool(_OBJECT_FILE.fullmatch(name))


def add_parser(sub):
    p = sub.add_parser(
        "simulate",
        help="write simulated labelled objects to a folder, for skpcd fit",
        description="Simulate labelled objects (the data of 'skpcd evaluate "
        "--data') and write them to a folder as 'skpcd fit' reads it: one "
        "point-cloud file per object (object_0000.ply ...) and labels.csv "
        "(file,label). The folder is filled under a temporary name and "
        "swapped in when whole; --overwrite replaces an earlier simulate's "
        "folder, never files skpcd did not write.",
    )
    p.add_argument("-o", "--output", required=True, help="output folder")
    p.add_argument(
        "--data",
        choices=tuple(DATA),
        default="urban",
        help="urban (default; make_urban_objects, 5 aerial-like classes), street "
        "(10 classes of street furniture, trees, cars cut from simulated mobile "
        "scans; the first run compiles the simulator for about a minute) or "
        "street-ugv (the same from UGV sweeps)",
    )
    p.add_argument(
        "--n-per-class",
        type=int,
        default=None,
        help="objects per class (default: 40 urban, 20 street)",
    )
    p.add_argument(
        "--format",
        default="ply",
        choices=SEGMENT_FORMATS,
        help="format of the object files (default ply)",
    )
    p.add_argument(
        "--random-state", type=int, default=0, help="seed of the objects (default 0)"
    )
    add_n_jobs(p)
    add_output_options(p)
    p.set_defaults(func=run_simulate)
    return p


def run_simulate(args):
    from skpcd.io import write_point_cloud
    from skpcd.io._atomic import atomic_folder, check_folder_output, check_writable

    out = Path(args.output)
    if out.exists() and not out.is_dir():
        raise CommandError("simulate", f"{out} exists and is not a folder")
    if out.is_dir() and any(out.iterdir()) and not args.overwrite:
        raise CommandError(
            "simulate",
            f"{out} is not empty; pass --overwrite to replace an earlier simulate's "
            "objects (files skpcd did not write are never deleted)",
        )
    if args.n_per_class is not None and args.n_per_class < 1:
        raise CommandError(
            "simulate", f"--n-per-class must be at least 1, got {args.n_per_class}"
        )
    check_folder_output(out, overwrite=True, owned=is_simulated_file)
    check_writable(out)
    clouds, labels, source = simulated_data(
        args.data, args.n_per_class, random_state=args.random_state, n_jobs=args.n_jobs
    )
    width = max(4, len(str(len(clouds) - 1)))
    with atomic_folder(out, overwrite=args.overwrite, owned=is_simulated_file) as tmp:
        names = []
        for i, cloud in enumerate(clouds):
            names.append(f"object_{i:0{width}d}.{args.format}")
            write_point_cloud(tmp / names[-1], cloud)
        with open(tmp / LABELS, "w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(["file", "label"])
            writer.writerows(zip(names, map(str, labels)))
    classes = sorted({str(y) for y in labels})
    print(f"data      {args.data}: {source}")
    print(
        f"written   {len(clouds)} objects of {len(classes)} classes "
        f"({', '.join(classes)}) and {LABELS} -> {out}"
    )
    return 0
