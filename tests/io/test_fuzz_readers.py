"""The text and NPY readers against corrupt input (issue 15, findings 6-8).

Each mutation of a small valid file is either read as the file says (an
independent parse of the file agrees with the points and fields returned)
or refused with :class:`~skpcd.exceptions.PointCloudFileError` naming the
file; never another exception, never a warning. The mutations run in a
subprocess under an address-space limit, so that a header that makes a
reader allocate memory the file does not back fails the test.
"""

import io
import json
import os
import subprocess
import sys
import textwrap
import time
import traceback
import warnings
import zipfile

import numpy as np
import pytest

from skpcd.exceptions import PointCloudFileError
from skpcd.io import read_point_cloud

# --- seeds -----------------------------------------------------------------

TEXT_SEEDS = {
    "plain.xyz": b"1 2 3\n4.5 -6 7e1\n-0.5 .25 8\n",
    "header.csv": b"X,Y,Z,Intensity\n1,2,3,10\n4,5,6,20\n7,8,9,30\n",
    "count.pts": b"3\n1 2 3 10 255 0 0\n4 5 6 11 0 255 0\n7 8 9 12 0 0 255\n",
    "named.txt": b"# scanner\nz y x id\n3 2 1 7\n// note\n6 5 4 8 # tail\n",
}


def _npy_bytes(array, version=None):
    buffer = io.BytesIO()
    np.lib.format.write_array(buffer, array, version=version, allow_pickle=False)
    return buffer.getvalue()


def _npy_seeds():
    rng = np.random.default_rng(0)
    record = np.dtype(
        [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("i", "<u2"), ("n", "<f4", (3,))]
    )
    structured = np.zeros(4, dtype=record)
    for name in "xyzi":
        structured[name] = rng.integers(0, 100, 4)
    structured["n"] = rng.normal(size=(4, 3))
    return {
        "plain.npy": _npy_bytes(rng.normal(size=(5, 3))),
        "fortran.npy": _npy_bytes(np.asfortranarray(rng.normal(size=(4, 4)), "f4")),
        "structured.npy": _npy_bytes(structured),
        "big-endian.npy": _npy_bytes(rng.normal(size=(3, 3)).astype(">f8")),
        "version2.npy": _npy_bytes(rng.integers(-9, 9, (3, 5), dtype="i2"), (2, 0)),
    }


# --- mutations -------------------------------------------------------------

_TEXT_BYTES = b"0123456789.,+-eE \t\n\r#/xyzXYZnaif\"'_\x00\xff"
_TEXT_TOKENS = [
    b"Infinity", b"nan", b"-inf", b"1.2.3", b"1_0", b"x", b"X", b"y", b"z", b"",
    b"1e999", b"\xd9\xa1", b"\xef\xbb\xbf", b'"x"', b"id", b"#", b"//", b"0",
    b"4294967296", b"  ", b",",
]  # fmt: skip
_NPY_SNIPPETS = [
    b"(2147483648, 3)", b"(5, 1000000000000)", b"(-1, 3)", b"(0, 3)", b"()",
    b"(5,)", b"'|O'", b"'<c16'", b"'V0'", b"'<U3'", b"[('x', '<f8', (2,))]",
    b"True", b"1", b"{", b"}", b"'", b"(", b"L", b"\x00", b"\n", b"PK\x03\x04",
]  # fmt: skip


def _mutate_text(data, rng):
    data = bytearray(data)
    for _ in range(int(rng.integers(1, 4))):
        op = int(rng.integers(8))
        at = int(rng.integers(len(data) + 1)) if data else 0
        if op == 0 and data:  # flip a bit
            data[min(at, len(data) - 1)] ^= 1 << int(rng.integers(8))
        elif op == 1 and data:  # replace a byte
            data[min(at, len(data) - 1)] = _TEXT_BYTES[rng.integers(len(_TEXT_BYTES))]
        elif op == 2:  # insert a byte
            data[at:at] = bytes([_TEXT_BYTES[rng.integers(len(_TEXT_BYTES))]])
        elif op == 3 and data:  # delete bytes
            del data[at : at + int(rng.integers(1, 4))]
        elif op == 4:  # replace a token
            tokens = bytes(data).replace(b",", b" , ").split(b" ")
            j = int(rng.integers(len(tokens)))
            tokens[j] = _TEXT_TOKENS[rng.integers(len(_TEXT_TOKENS))]
            data = bytearray(b" ".join(tokens).replace(b" , ", b","))
        elif op == 5:  # duplicate, drop or swap lines
            lines = bytes(data).split(b"\n")
            i, j = rng.integers(len(lines), size=2)
            choice = int(rng.integers(3))
            if choice == 0:
                lines.insert(int(i), lines[j])
            elif choice == 1 and len(lines) > 1:
                del lines[int(i)]
            else:
                lines[i], lines[j] = lines[j], lines[i]
            data = bytearray(b"\n".join(lines))
        elif op == 6:  # truncate
            del data[at:]
        else:  # something at the start
            data[0:0] = _TEXT_TOKENS[rng.integers(len(_TEXT_TOKENS))]
    return bytes(data)


def _mutate_npy(data, rng):
    data = bytearray(data)
    header_end = data.index(b"\n") + 1 if b"\n" in data else len(data)
    for _ in range(int(rng.integers(1, 3))):
        op = int(rng.integers(7))
        if op <= 1 and data:  # flip a bit, mostly in the header
            end = header_end if op == 0 else len(data)
            at = int(rng.integers(max(end, 1)))
            data[min(at, len(data) - 1)] ^= 1 << int(rng.integers(8))
        elif op == 2:  # replace part of the header text
            text = bytes(data[:header_end])
            snippet = _NPY_SNIPPETS[rng.integers(len(_NPY_SNIPPETS))]
            for old in (b"(5, 3)", b"(4, 4)", b"(4,)", b"(3, 3)", b"(3, 5)"):
                if old in text and rng.random() < 0.7:
                    new = snippet if snippet.startswith(b"(") else old
                    data[:header_end] = text.replace(old, new.ljust(len(old)))
                    break
            else:
                at = int(rng.integers(10, max(header_end, 11)))
                data[at : at + len(snippet)] = snippet
        elif op == 3:  # a different descr, same header length when it fits
            text = bytes(data[:header_end])
            snippet = _NPY_SNIPPETS[rng.integers(6, 11)]
            start = text.find(b"'descr': ") + len(b"'descr': ")
            stop = text.find(b", 'fortran_order'")
            if start > 8 and stop > start:
                data[start:stop] = snippet
        elif op == 4:  # truncate
            del data[int(rng.integers(len(data) + 1)) :]
        elif op == 5:  # append
            data += bytes(
                rng.integers(0, 256, int(rng.integers(1, 64)), dtype=np.uint8)
            )
        else:  # toggle the order flag
            data[:header_end] = bytes(data[:header_end]).replace(b"False", b"True ")
    return bytes(data)


# --- what a correct read returns -------------------------------------------


def _expected_text(data):
    """Points and fields of a text cloud, parsed with float() and str.split,
    or None when this plain parse fails."""
    text = data.decode("utf-8-sig", errors="replace")
    text = text.replace("\r\n", "\n").replace("\r", "\n")
    rows = []
    delimiter = None
    for line in text.split("\n"):
        if line.strip().startswith(("#", "//")):
            continue
        body = line.split("#", 1)[0].split("//", 1)[0]
        if not body.strip():
            continue
        if delimiter is None and not rows:
            delimiter = "," if "," in line else " "
        if delimiter == ",":
            rows.append([t.strip() for t in body.strip().split(",")])
        else:
            rows.append(body.split())
    try:
        first = [float(t) for t in rows[0]]
    except ValueError:
        names = [t.strip("\"'").strip().lower() for t in rows[0]]
        rows = rows[1:]
    else:
        names = None
        if len(rows[0]) == 1 and rows[0][0].isdigit():
            declared = int(first[0])
            rows = rows[1:]
            if declared != len(rows):
                return None
    try:
        table = np.array([[float(t) for t in row] for row in rows], dtype=float)
    except ValueError:
        return None
    if table.ndim != 2 or table.shape[1] < 3:
        return None
    names = names or ["x", "y", "z"] + [f"field_{j}" for j in range(3, table.shape[1])]
    columns = dict(zip(names, table.T))
    points = np.column_stack([columns.pop(c) for c in "xyz"])
    return points, columns


def _expected_npy(path):
    array = np.load(path, allow_pickle=False)
    if array.dtype.names:
        points = np.column_stack([array[c].astype(float) for c in "xyz"])
        extras = {
            n: array[n].reshape(len(array), -1) if array[n].ndim > 2 else array[n]
            for n in array.dtype.names
            if n not in "xyz"
        }
        return points, extras
    extras = {f"field_{j}": array[:, j] for j in range(3, array.shape[1])}
    return array[:, :3].astype(float), extras


def _check_read(path, expected):
    """One read: a PointCloudFileError naming ``path``, or ``expected(path)``.
    Returns "error" or "read"; raises AssertionError otherwise."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            points, extras = read_point_cloud(path, fields="all", nonfinite="keep")
    except PointCloudFileError as exc:
        assert exc.path == str(path), (exc.path, path)
        assert str(exc).startswith(f"{path}: "), str(exc)
        return "error"
    want = expected(path)
    assert want is not None, "read a file that a plain parse refuses"
    want_points, want_extras = want
    np.testing.assert_array_equal(points, want_points)
    assert list(extras) == list(want_extras)
    for name, values in want_extras.items():
        np.testing.assert_array_equal(extras[name], values)
    return "read"


def fuzz(kind, folder, n_mutations, seed=0):
    """Run ``n_mutations`` of each seed file of ``kind`` ("text" or "npy");
    returns ``{"read": ..., "error": ..., "failures": [...], "seconds": ...}``."""
    rng = np.random.default_rng(seed)
    seeds = TEXT_SEEDS if kind == "text" else _npy_seeds()
    mutate = _mutate_text if kind == "text" else _mutate_npy
    if kind == "text":

        def expected(path):
            return _expected_text(path.read_bytes())

    else:
        expected = _expected_npy
    counts = {"read": 0, "error": 0}
    failures = []
    start = time.perf_counter()
    for name, data in seeds.items():
        assert _check_read(_write(folder, name, data), expected) == "read", name
        for i in range(n_mutations):
            mutated = mutate(data, rng)
            path = _write(folder, f"m{i}-{name}", mutated)
            try:
                counts[_check_read(path, expected)] += 1
            except BaseException as exc:  # every escape is a finding
                if isinstance(exc, KeyboardInterrupt):
                    raise
                failures.append(
                    f"{name} mutation {i}: {mutated[:300]!r}\n"
                    + "".join(traceback.format_exception(exc)[-3:])
                )
            path.unlink()
    counts["failures"] = failures
    counts["seconds"] = round(time.perf_counter() - start, 2)
    return counts


def _write(folder, name, data):
    path = folder / name
    path.write_bytes(data)
    return path


# --- the fuzz tests, under a memory limit ------------------------------------

_LIMIT = """
import json, pathlib, resource, sys
import importlib.util

spec = importlib.util.spec_from_file_location("fuzz_readers", {module!r})
module = importlib.util.module_from_spec(spec)
spec.loader.exec_module(module)
with open("/proc/self/status") as f:
    size = [int(line.split()[1]) for line in f if line.startswith("VmSize")][0]
limit = size * 1024 + {headroom}
resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
result = module.fuzz({kind!r}, pathlib.Path({folder!r}), {n})
result["limit_mb"] = limit // 2**20
print(json.dumps(result))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc, RLIMIT_AS")
@pytest.mark.parametrize("kind", ["text", "npy"])
def test_fuzz_reader(tmp_path, kind):
    # 4-5 seeds x 80 mutations; the address space is what the interpreter
    # holds with skpcd imported plus 256 MiB: far less than any corrupt
    # header could ask for (the 416-byte NPY of finding 7 asked for 48 GiB)
    code = _LIMIT.format(
        module=__file__, headroom=256 * 2**20, kind=kind, folder=str(tmp_path), n=80
    )
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    done = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
    )
    assert done.returncode == 0, done.stderr[-4000:]
    result = json.loads(done.stdout.splitlines()[-1])
    assert not result["failures"], "\n\n".join(result["failures"][:5])
    total = result["read"] + result["error"]
    assert total == 80 * (len(TEXT_SEEDS) if kind == "text" else len(_npy_seeds()))
    # the mutations reach both outcomes
    assert result["read"] > 0.05 * total and result["error"] > 0.2 * total, result


# --- NPY regressions (issue 15, finding 7) ---------------------------------


def _npy_with_header(tmp_path, header, data=b""):
    """An .npy file of version 1.0 with ``header`` as its header text."""
    text = header.ljust(117) + b"\n"  # 128 bytes with the signature
    path = tmp_path / "a.npy"
    path.write_bytes(
        b"\x93NUMPY\x01\x00" + len(text).to_bytes(2, "little") + text + data
    )
    return path


@pytest.mark.parametrize(
    "header",
    [
        # was: tokenize.TokenError (from NumPy's fallback parser)
        b"{'descr': '<f8', 'fortran_order': False, 'shape': (2, 3), ",
        b"{'descr': '<f8', 'fortran_order': False, 'shape': (2, 3)} )",
        b"{'descr': '<f8', 'fortran_order': False}",
        b"{'descr': 'nonsense', 'fortran_order': False, 'shape': (2, 3)}",
        b"{'descr': '<f8', 'fortran_order': 0, 'shape': (2, 3)}",
        b"{'descr': '<f8', 'fortran_order': False, 'shape': (2.0, 3)}",
        b"[" * 60,
    ],
)
def test_npy_corrupt_header_is_a_clean_error(tmp_path, header):
    path = _npy_with_header(tmp_path, header, b"\0" * 48)
    with pytest.raises(PointCloudFileError, match=r"corrupt \.npy header") as info:
        read_point_cloud(path)
    assert str(info.value).startswith(f"{path}: ")


def test_npy_shape_larger_than_the_file_allocates_nothing(tmp_path):
    # was: MemoryError "Unable to allocate 48.0 GiB" without the file name
    header = b"{'descr': '<f8', 'fortran_order': False, 'shape': (2147483648, 3), }"
    path = _npy_with_header(tmp_path, header, b"\0" * 288)
    assert path.stat().st_size == 416
    with pytest.raises(
        PointCloudFileError,
        match=r"declares shape \(2147483648, 3\) of float64 \(51539607552 bytes of "
        r"data after a 128-byte header, 51539607680 bytes in all\), but the file "
        r"holds 416 bytes \(truncated\)",
    ) as info:
        read_point_cloud(path)
    assert str(info.value).startswith(f"{path}: ")
    path.write_bytes(_npy_bytes(np.ones((2, 3))) + b"\0")
    with pytest.raises(PointCloudFileError, match=r"holds 177 bytes \(trailing bytes"):
        read_point_cloud(path)


def test_npz_renamed_npy_is_a_clean_error(tmp_path):
    # was: AttributeError: 'NpzFile' object has no attribute 'dtype'
    path = tmp_path / "a.npy"
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("points.npy", _npy_bytes(np.ones((2, 3))))
    with pytest.raises(PointCloudFileError, match=r"a\.npy: this is a zip archive"):
        read_point_cloud(path)
    path.write_bytes(b"not numpy at all")
    with pytest.raises(PointCloudFileError, match="no NumPy signature"):
        read_point_cloud(path)


def test_npy_structured_subarrays_are_fields_never_points(tmp_path):
    path = tmp_path / "a.npy"
    # was: an (n, 4) "points" array
    bad = np.zeros(3, dtype=[("x", "<f8", (2,)), ("y", "<f8"), ("z", "<f8")])
    np.save(path, bad)
    with pytest.raises(PointCloudFileError, match="field 'x' must hold one number"):
        read_point_cloud(path)
    np.save(path, np.zeros(3, dtype=[("x", "<f8"), ("y", "<f8"), ("z", "S4")]))
    with pytest.raises(PointCloudFileError, match="field 'z' must hold one number"):
        read_point_cloud(path)
    good = np.zeros(
        3,
        dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("n", "<f4", (2,)),
               ("m", "<i2", (2, 2))],
    )  # fmt: skip
    good["x"], good["n"], good["m"] = [1, 2, 3], [[1, 2]] * 3, 7
    np.save(path, good)
    points, extras = read_point_cloud(path, fields="all")
    assert points.shape == (3, 3)
    np.testing.assert_array_equal(points[:, 0], [1, 2, 3])
    assert extras["n"].shape == (3, 2) and extras["m"].shape == (3, 4)


def test_npy_objects_and_complex_numbers_are_refused(tmp_path):
    path = tmp_path / "a.npy"
    np.save(path, np.array([[1, "a", None]], dtype=object), allow_pickle=True)
    with pytest.raises(PointCloudFileError, match="never unpickles"):
        read_point_cloud(path)
    np.save(path, np.zeros((2, 3), complex))
    with pytest.raises(PointCloudFileError, match="integers or floats"):
        read_point_cloud(path)
    np.save(path, np.zeros((0, 3)))
    with pytest.raises(PointCloudFileError, match="no points"):
        read_point_cloud(path)


@pytest.mark.parametrize("version", [(1, 0), (2, 0), (3, 0)])
def test_npy_layouts_read_as_numpy_reads_them(tmp_path, version):
    path = tmp_path / "a.npy"
    plain = np.asfortranarray(np.arange(12.0).reshape(4, 3))
    path.write_bytes(_npy_bytes(plain, version))
    np.testing.assert_array_equal(read_point_cloud(path), plain)


def test_npy_sub_array_dtype_adds_axes(tmp_path):
    # a header whose descr is a sub-array (numpy.load itself fails on a real
    # file): shape (4,) of (3,) floats is (4, 3)
    header = b"{'descr': ('<f8', (3,)), 'fortran_order': False, 'shape': (4,), }"
    path = _npy_with_header(tmp_path, header, np.arange(12.0).tobytes())
    np.testing.assert_array_equal(read_point_cloud(path), np.arange(12.0).reshape(4, 3))
