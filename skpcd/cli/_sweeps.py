"""``skpcd identify SCENE [SCENE ...] -o FOLDER``: scenes (sweeps of a
spinning sensor, say) identified one after the other in this process, the
model loaded and the numba kernels compiled once, each written to
FOLDER/<its file name> with its ``.classes.csv`` as ``skpcd identify``
writes one scene. Every output is checked before the first scene; each is
written atomically, so that an interrupt or a scene that cannot be read
leaves the scenes done before whole and nothing of the one under way."""

import time
from argparse import Namespace
from pathlib import Path

from skpcd.cli._common import CommandError, check_not_an_input, side_file

# Files of a folder of scenes that are not scenes: the legends identify
# writes beside its outputs, the summaries of folders of segments.
_NOT_SCENES = (".classes.csv", "labels.csv", "segments.csv")
# Formats that cannot hold the fields identify writes.
_NO_FIELDS = {".bin": "a KITTI .bin scan holds x, y, z and intensity only"}


def is_several(scenes):
    """Whether the SCENE arguments ask for the streamed form: several, or
    a folder."""
    return len(scenes) > 1 or Path(scenes[0]).is_dir()


def scene_files(scenes, command):
    """The files of the SCENE arguments, in order: a file as given, a
    folder's point-cloud files sorted by name (hidden files, legends and
    summaries left out)."""
    from skpcd.exceptions import MissingFileError
    from skpcd.io import SUPPORTED_EXTENSIONS

    files = []
    for scene in map(Path, scenes):
        if scene.is_dir():
            found = sorted(
                (
                    p
                    for p in scene.iterdir()
                    if p.suffix.lower() in SUPPORTED_EXTENSIONS
                    and not p.name.startswith(".")
                    and not p.name.endswith(_NOT_SCENES)
                    and p.is_file()
                ),
                key=lambda p: p.name,
            )
            if not found:
                raise CommandError(
                    command,
                    f"{scene} holds no point-cloud file ("
                    + " ".join(SUPPORTED_EXTENSIONS)
                    + ")",
                )
            files += found
        elif scene.is_file():
            files.append(scene)
        else:
            raise MissingFileError(scene, "no such file")
    return files


def plan_outputs(args, files, command):
    """``[(scene, output, legend), ...]`` for ``files``, each output
    FOLDER/<scene's name>, refused before any work (one line each) when
    --inventory is given, FOLDER is a file or an input's folder, two
    scenes share a name, an output is an input or exists without
    --overwrite, or the folder cannot be written."""
    from skpcd.io._atomic import check_writable

    if args.inventory is not None:
        raise CommandError(
            command, "--inventory takes one scene; identify several one at a time"
        )
    out = Path(args.output)
    if out.exists() and not out.is_dir():
        raise CommandError(
            command, f"{out} is a file; with several scenes -o names a folder"
        )
    named = {}
    for scene in files:
        if scene.name in named:
            raise CommandError(
                command,
                f"two scenes are named {scene.name} ({named[scene.name]} and "
                f"{scene}): their outputs in {out} would be the same file",
            )
        named[scene.name] = scene
        if scene.suffix.lower() in _NO_FIELDS:
            raise CommandError(
                command,
                f"{scene}: {_NO_FIELDS[scene.suffix.lower()]}, not the classes; "
                "identify it alone with -o NAME.las (or .ply)",
            )
    if out.resolve() in {scene.resolve().parent for scene in files}:
        raise CommandError(
            command,
            f"the output folder {out} holds input scenes; write the outputs "
            "to another folder",
        )
    inputs = [*files, None if args.model is None else Path(args.model)]
    plans, existing = [], []
    for scene in files:
        target = out / scene.name
        legend = side_file(target, "classes.csv")
        for path in (target, legend):
            check_not_an_input(path, command, inputs)
            if path.is_dir():
                raise CommandError(command, f"{path} is a folder")
            if path.exists():
                existing.append(path)
        plans.append((scene, target, legend))
    if existing and not args.overwrite:
        more = f" and {len(existing) - 1} more outputs" if len(existing) > 1 else ""
        raise CommandError(
            command, f"{existing[0]}{more} exist; pass --overwrite to replace them"
        )
    check_writable(out / files[0].name)
    return plans


def run_sweeps(args):
    """identify each scene of ``args.scene`` into the folder ``args.output``."""
    from skpcd.cli._common import load_model_for

    command = "identify"
    files = scene_files(args.scene, command)
    plans = plan_outputs(args, files, command)
    model = load_model_for(args, command)
    out = Path(args.output)
    made = [p for p in (out, *out.parents) if not p.exists()]
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    try:
        done = _identify_each(args, model, plans, out, command)
    finally:
        # the folders made for the outputs go again when none was written
        for folder in made:
            if folder.is_dir() and not any(folder.iterdir()):
                folder.rmdir()
    seconds = time.perf_counter() - start
    if not args.quiet:
        print(
            f"identified {done} scenes in {seconds:.1f} s "
            f"({done / max(seconds, 1e-9):.1f} sweeps per second) -> {out}"
        )
    return 0


def _identify_each(args, model, plans, out, command):
    """identify each planned scene in turn; returns how many were."""
    from skpcd.cli._identify import identify_scene
    from skpcd.exceptions import PointCloudFileError
    from skpcd.utils._progress import silenced

    done = 0
    for scene, target, legend in plans:
        # each scene alone, as identify SCENE -o OUTPUT --quiet would run it
        one = Namespace(**{**vars(args), "scene": str(scene), "quiet": True})
        one.output = str(target)
        began = time.perf_counter()
        try:
            with silenced(True):
                _, _, result = identify_scene(one, model, target, legend)
        except (PointCloudFileError, CommandError) as exc:
            raise _stopped_at(scene, exc, done, out, command) from exc
        done += 1
        if not args.quiet:
            print(
                f"{scene.name}  {len(result.labels)} points  "
                f"{result.n_segments} segments  "
                f"{time.perf_counter() - began:.3f} s",
                flush=True,
            )
    return done


def _stopped_at(scene, exc, done, out, command):
    """The one-line error of a scene that cannot be identified, naming it
    and the outputs written before it (they stay)."""
    text = str(exc.code if isinstance(exc, SystemExit) else exc)
    text = text.removeprefix(f"skpcd {command}: ")
    if not text.startswith(str(scene)):
        text = f"{scene}: {text}"
    return CommandError(
        command,
        f"error: {text} (stopped there; the {done} scenes before it are "
        f"written in {out})",
    )
