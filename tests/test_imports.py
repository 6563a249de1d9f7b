"""The one rule for imports inside functions (CONTRIBUTING.md): the library
imports at the top of its modules; a function imports only an optional or
heavy dependency, loaded on first use, and the CLI imports the library inside
its commands so that ``skpcd --help`` starts fast."""

import ast
import re
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
    # the quoted entries of pyproject.toml's ``dependencies = [...]`` (no
    # tomllib: Python 3.10 is supported)
    text = (ROOT.parent / "pyproject.toml").read_text()
    block = text.split("\ndependencies = [", 1)[1].split("\n]", 1)[0]
    entries = re.findall(r'^\s*"([^"]+)"', block, flags=re.M)
    names = [re.split(r"[<>=!~\[; ]", d, maxsplit=1)[0] for d in entries]
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


def _package(module):
    """The package of a module of skpcd: ``skpcd.io._las`` -> ``io``; a
    module at the top (``skpcd._interrupts``) is its own."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def _private_names_across_packages(root):
    found = []
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root.parent).with_suffix("")
        here = ".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.ImportFrom) or not node.module:
                continue
            if not node.module.startswith(root.name) or node.level:
                continue
            for alias in node.names:
                target = f"{node.module}.{alias.name}"
                # a name imported from another package, or a module of its
                # own imported by a private name, must be public
                other = _package(node.module) != _package(here)
                dunder = alias.name.startswith("__") and alias.name.endswith("__")
                if alias.name.startswith("_") and other and not dunder:
                    found.append(f"{rel}:{node.lineno} {target}")
    return found


def test_names_used_across_packages_are_public():
    assert _private_names_across_packages(ROOT) == []


def test_the_rule_sees_a_private_name_from_another_package(tmp_path):
    pkg = tmp_path / "skpcd"
    (pkg / "cli").mkdir(parents=True)
    (pkg / "io").mkdir()
    (pkg / "cli" / "_x.py").write_text(
        "from skpcd.io._f import _hidden, shown\nfrom skpcd import _interrupts\n"
    )
    (pkg / "io" / "_g.py").write_text("from skpcd.io._f import _hidden\n")
    assert _private_names_across_packages(pkg) == [
        "skpcd/cli/_x:1 skpcd.io._f._hidden",
        "skpcd/cli/_x:2 skpcd._interrupts",
    ]


def test_modules_are_rooms_of_a_reasonable_size():
    # a module over 800 lines holds two things; a command's module over 450
    # lines, more than its command (the supervision of the process, a second
    # command): split them where they hold two things
    too_long = []
    for path in sorted(ROOT.rglob("*.py")):
        limit = 450 if "cli" in path.relative_to(ROOT).parts else 800
        n = len(path.read_text().splitlines())
        if n > limit:
            too_long.append(f"{path.relative_to(ROOT.parent)}: {n} > {limit}")
    assert too_long == []
