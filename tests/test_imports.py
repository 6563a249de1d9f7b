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
