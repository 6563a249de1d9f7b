"""The commands the README shows parse as written: every command and option it
names exists (the parser's own checks, no work done)."""

import re
import shlex
from pathlib import Path

import pytest

from skpcd.cli import build_parser

README = Path(__file__).resolve().parents[2] / "README.md"


def _readme_commands():
    text = README.read_text()
    blocks = re.findall(r"```bash\n(.*?)```", text, flags=re.S)
    commands = []
    for block in blocks[1:]:  # the first block installs and runs the tests
        for line in block.splitlines():
            line = line.split("#", 1)[0].strip()
            if line.startswith("skpcd "):
                commands.append(line)
    return commands


COMMANDS = _readme_commands()


def test_the_readme_shows_commands():
    assert len(COMMANDS) >= 15


@pytest.mark.parametrize("line", COMMANDS)
def test_a_readme_command_parses(line, capsys):
    argv = shlex.split(line)[1:]
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as e:  # argparse's refusal
        pytest.fail(f"{line!r}: {capsys.readouterr().err.strip()} (status {e.code})")
    assert args.command == argv[0]


def test_the_readme_names_the_defaults_the_code_has():
    # before: the README called CSF GroundFilter's default, though it is
    # SMRF, and segment_scene chooses the filter from the scan
    import inspect

    from skpcd.classification._street import STREET_MODEL_CLASSES
    from skpcd.segmentation import EuclideanClusters, GroundFilter, segment_scene
    from skpcd.segmentation._dbscan import EPS_SCALE

    text = " ".join(README.read_text().split())
    method = re.search(r"`GroundFilter` \((\w+), its default method", text)
    assert method and method[1].lower() == GroundFilter().method
    ground = inspect.signature(segment_scene).parameters["ground"].default
    assert f'(`ground="{ground}"`: ' in text
    assert f"eps = {EPS_SCALE:g} x the knee" in text
    e = EuclideanClusters()
    assert f"`EuclideanClusters` ({e.eps:g} m and {e.min_cluster_size} " in text
    shipped = re.search(r"a street model shipped in the package \(([^)]*)\)", text)
    names = [n.strip().removeprefix("and ") for n in shipped[1].split(",")]
    assert [n.replace(" ", "_") for n in names] == list(STREET_MODEL_CLASSES)
