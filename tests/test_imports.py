"""The one rule for imports inside functions (CONTRIBUTING.md): the library
imports at the top of its modules; a function imports only an optional or
heavy dependency, loaded on first use, and the CLI imports the library inside
its commands so that ``skpcd --help`` starts fast."""

import ast
from pathlib import Path

import skpcd

# optional extras or heavy libraries (or heavy parts of one) that a module loads
# when first used
ON_FIRST_USE = {
    "CSF",
    "dask",
    "distributed",
    "laspy",
    "lazrs",
    "matplotlib",
    "open3d",
    "pynndescent",
    "pyogrio",  # the gis extra: GeoPackage inventories
    "skops",
    # the spacing's search among many points (numba, and skpcd.utils, which
    # loads scikit-learn): `skpcd info` loads the spacing module alone and
    # needs neither on a small file
    "skpcd.preprocessing._spacing_kernels",
    "skpcd.utils._geometry",
    "sklearn.tree",
    "tqdm",  # progress bars: drawn only on a terminal, not at --help
}

ROOT = Path(skpcd.__file__).parent


def _local_imports(path):
    tree = ast.parse(path.read_text())
    for fn in ast.walk(tree):
        if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
            for node in ast.walk(fn):
                if isinstance(node, ast.Import):
                    yield node.lineno, node.names[0].name
                elif isinstance(node, ast.ImportFrom):
                    yield node.lineno, node.module or ""


def test_functions_import_only_what_is_loaded_on_first_use():
    offending = [
        f"{path.relative_to(ROOT.parent)}:{line} imports {module}"
        for path in sorted(ROOT.rglob("*.py"))
        if "cli" not in path.relative_to(ROOT).parts
        for line, module in _local_imports(path)
        if not any(module == m or module.startswith(m + ".") for m in ON_FIRST_USE)
    ]
    assert offending == []


def test_the_rule_sees_a_local_import(tmp_path):
    module = tmp_path / "m.py"
    module.write_text("def f():\n    import numpy\n    from skpcd import io\n")
    assert list(_local_imports(module)) == [(2, "numpy"), (3, "skpcd")]


# the import names of the distributions pyproject.toml requires, where they
# differ from the distribution's name
_IMPORT_NAMES = {"cloth-simulation-filter": "CSF", "scikit-learn": "sklearn"}


def _required_modules():
    import re
    import tomllib

    project = tomllib.loads((ROOT.parent / "pyproject.toml").read_text())["project"]
    names = [re.split(r"[<>=!~\[; ]", d, maxsplit=1)[0] for d in project["dependencies"]]
    return {_IMPORT_NAMES.get(n, n.replace("-", "_")) for n in names}


def test_tests_do_not_skip_when_a_required_dependency_is_missing():
    # a required dependency that is missing is an error, not a skip: no
    # test may importorskip one (laspy, lazrs, CSF are required)
    required = _required_modules()
    assert {"laspy", "lazrs", "CSF", "numpy"} <= required
    skipped = []
    for path in sorted((ROOT.parent / "tests").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if (
                isinstance(node, ast.Call)
                and getattr(node.func, "attr", None) == "importorskip"
                and node.args
                and isinstance(node.args[0], ast.Constant)
                and node.args[0].value in required  # (not a version's submodule)
            ):
                skipped.append(f"{path.name}:{node.lineno} {node.args[0].value}")
    assert skipped == []
