import subprocess
import sys

import skpcd


def test_import_is_light():
    code = (
        "import sys, skpcd; "
        "heavy = ('numba', 'pynndescent', 'sklearn', 'scipy'); "
        "heavy = [m for m in heavy if m in sys.modules]; "
        "print(heavy)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == "[]"


def test_public_names_resolve():
    for name in skpcd.__all__:
        assert getattr(skpcd, name) is not None
    assert skpcd.__version__
