"""The borrowed arrays of the numba kernels never leave the kernel.

:func:`skpcd.utils._numba.borrow` drops an array's reference count: safe
only while the owner outlives every use. The kernels borrow their
arguments and their own scratch (kept alive with ``keep``); a borrowed
array returned, yielded or stored in another array would outlive its
owner. This test reads every module that imports ``borrow`` and checks
that no function returns or yields a borrowed name, and that a function
that borrows a scratch array it allocated keeps that array alive.
"""

import ast
from pathlib import Path

import pytest

import skpcd

PACKAGE = Path(skpcd.__file__).parent
KERNEL_MODULES = sorted(
    p
    for p in PACKAGE.rglob("*.py")
    if "from skpcd.utils._numba import" in p.read_text(encoding="utf-8")
)


def _is_borrow(value):
    return isinstance(value, ast.Call) and getattr(value.func, "id", None) == "borrow"


def _borrowed_names(func):
    """Names bound to ``borrow(...)`` in a function (tuple targets too:
    ``a, b = borrow(a), borrow(b)`` and ``a, b = borrow(a, b)``)."""
    names = set()
    for node in ast.walk(func):
        if not isinstance(node, ast.Assign):
            continue
        targets = node.targets[0]
        targets = targets.elts if isinstance(targets, ast.Tuple) else [targets]
        if _is_borrow(node.value) and len(node.value.args) > 1:
            values = [node.value] * len(targets)
        elif isinstance(node.value, ast.Tuple):
            values = node.value.elts
        else:
            values = [node.value]
        for target, value in zip(targets, values):
            if _is_borrow(value) and isinstance(target, ast.Name):
                names.add(target.id)
    return names


def _escaping(func, borrowed):
    """Borrowed names returned or yielded (directly or in a tuple)."""
    out = []
    for node in ast.walk(func):
        if isinstance(node, (ast.Return, ast.Yield)) and node.value is not None:
            values = (
                node.value.elts if isinstance(node.value, ast.Tuple) else [node.value]
            )
            out += [
                v.id for v in values if isinstance(v, ast.Name) and v.id in borrowed
            ]
    return out


def _unkept_scratch(func):
    """Arrays allocated in the function (``np.empty``...), borrowed from,
    and not kept alive with ``keep(...)``."""
    allocated, borrowed_from, kept = set(), set(), set()
    for node in ast.walk(func):
        if isinstance(node, ast.Assign) and isinstance(node.value, ast.Call):
            f = node.value.func
            if isinstance(f, ast.Attribute) and f.attr in ("empty", "zeros", "full"):
                allocated |= {t.id for t in node.targets if isinstance(t, ast.Name)}
        if isinstance(node, ast.Call) and getattr(node.func, "id", None) in (
            "borrow",
            "keep",
        ):
            names = {
                n.id
                for arg in node.args
                for n in ast.walk(arg)
                if isinstance(n, ast.Name)
            }
            (kept if node.func.id == "keep" else borrowed_from).update(names)
    return (allocated & borrowed_from) - kept


def test_kernel_modules_found():
    names = {p.name for p in KERNEL_MODULES}
    assert {"_grid_kernels.py", "_pfh_kernels.py", "_cluster_kernels.py"} <= names


@pytest.mark.parametrize("path", KERNEL_MODULES, ids=lambda p: p.name)
def test_borrowed_arrays_never_escape(path):
    tree = ast.parse(path.read_text(encoding="utf-8"))
    for func in ast.walk(tree):
        if not isinstance(func, ast.FunctionDef):
            continue
        borrowed = _borrowed_names(func)
        assert not _escaping(func, borrowed), (path.name, func.name)
        assert not _unkept_scratch(func), (path.name, func.name)
