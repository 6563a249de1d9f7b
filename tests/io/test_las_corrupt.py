"""LAS/LAZ files whose header or structure lies (issue 15, items 1-2).

Every file is written here with laspy and corrupted byte by byte; no binary is
committed. Reads that used to abort the process, hang or allocate gigabytes
run in a child process with an address-space limit (1 GiB above what the
imports take) and an alarm, so that a crash, a hang or an allocation shows
as a failed test instead of taking pytest down.
"""

import io
import json
import re
import struct
import subprocess
import sys
import textwrap

import laspy
import numpy as np
import pytest

from skpcd.exceptions import PointCloudFileError
from skpcd.io import iter_points, read_las_extent, read_point_cloud

# --- writing and corrupting files -----------------------------------------


def _write(path, n=1000, point_format=6, version="1.4", evlr=False, seed=0):
    rng = np.random.default_rng(seed)
    header = laspy.LasHeader(point_format=point_format, version=version)
    header.add_extra_dims([laspy.ExtraBytesParams("reflectance", "float32")])
    header.scales = [0.01, 0.01, 0.01]
    las = laspy.LasData(header)
    las.x = rng.uniform(0, 100, n)
    las.y = rng.uniform(0, 100, n)
    las.z = rng.uniform(0, 20, n)
    las.classification = rng.integers(1, 10, n)
    las.intensity = rng.integers(0, 65535, n)
    las.reflectance = rng.random(n).astype(np.float32)
    if evlr:
        las.evlrs = laspy.vlrs.vlrlist.VLRList([laspy.VLR("test", 1, "e", b"x" * 40)])
    las.write(str(path))
    return bytearray(path.read_bytes())


def _offset(data):
    return struct.unpack_from("<I", data, 96)[0]


def _laszip(data):
    """Byte position of the laszip VLR's record data."""
    return data.index(b"laszip encoded") - 2 + 54


def _put(data, fmt, pos, *values):
    data = bytearray(data)
    struct.pack_into(fmt, data, pos, *values)
    return data


def _expect(path, match, reader):
    with pytest.raises(PointCloudFileError, match=match) as excinfo:
        reader(path)
    assert str(path) in str(excinfo.value)
    return str(excinfo.value)


def _read(path):
    return read_point_cloud(path, fields="all", nonfinite="keep")


def _iter(path):
    return sum(len(c) for c in iter_points(path, chunk_size=300))


READERS = [_read, _iter, read_las_extent]
CHILD_READERS = ("read", "iter", "extent")


# --- the reads that crashed, hung or allocated: in a child process ---------

CHILD = textwrap.dedent(
    """
    import json, resource, signal, sys
    from skpcd.exceptions import PointCloudFileError
    from skpcd.io import iter_points, read_las_extent, read_point_cloud

    pages = int(open("/proc/self/statm").read().split()[0])
    limit = pages * resource.getpagesize() + (1 << 30)
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))

    def hang(*_):
        raise TimeoutError("no answer within 30 s")

    signal.signal(signal.SIGALRM, hang)
    READERS = {
        "read": lambda p: read_point_cloud(p, fields="all", nonfinite="keep"),
        "iter": lambda p: sum(len(c) for c in iter_points(p, chunk_size=300)),
        "extent": read_las_extent,
    }
    for case, path, reader in json.loads(sys.argv[1]):
        print(json.dumps({"case": case}), flush=True)
        signal.alarm(30)
        try:
            READERS[reader](path)
            outcome, message = "no error", ""
        except PointCloudFileError as exc:
            outcome, message = "PointCloudFileError", str(exc)
        except BaseException as exc:
            outcome, message = type(exc).__name__, str(exc)[:300]
        signal.alarm(0)
        print(json.dumps({"case": case, "outcome": outcome, "message": message}))
    """
)


def _in_child(cases):
    """Run ``(case, path, reader)`` reads in child processes; a child that
    dies is restarted on the cases after the one it died on."""
    results = {}
    todo = list(cases)
    while todo:
        proc = subprocess.run(
            [sys.executable, "-c", CHILD, json.dumps(todo)],
            capture_output=True,
            text=True,
            timeout=600,
        )
        started = None
        for line in proc.stdout.splitlines():
            record = json.loads(line)
            if "outcome" in record:
                results[record["case"]] = (record["outcome"], record["message"])
                started = None
            else:
                started = record["case"]
        if started is None:
            assert not [c for c, _, _ in todo if c not in results], proc.stderr
            break
        results[started] = (f"process died (rc {proc.returncode})", proc.stderr[-300:])
        todo = [t for t in todo if t[0] not in results]
    return results


@pytest.fixture(scope="module")
def dangerous(tmp_path_factory):
    folder = tmp_path_factory.mktemp("corrupt")
    laz = _write(folder / "base.laz", n=60_000)
    las = _write(folder / "base.las", n=1000)
    las12 = _write(folder / "base12.las", n=1000, point_format=3, version="1.2")
    small = _write(folder / "small.las", n=10, point_format=1, version="1.2")
    with_evlr = _write(folder / "evlr.las", n=1000, evlr=True)
    offset = _offset(laz)
    files = {
        # issue 15.1: one field of the laszip VLR aborted the process
        "chunk_size": (laz, "<I", _laszip(laz) + 12, 0xFFFF0000),
        # issue 15.1: num_items = 0 raised lazrs's PanicException
        "no_items": (laz, "<H", _laszip(laz) + 32, 0),
        # a chunk table offset past the end: lazrs allocated 3.4 GB and aborted
        "table_offset": (laz, "<q", offset, 2**62),
        # a layer size of the first chunk: lazrs allocated 2 GB and aborted
        "layer_size": (laz, "<I", offset + 8 + 34 + 4, 0x7FFFFFF0),
        # issue 15.2: number_of_vlrs = 2**32 - 1 in a small file: ran for ever
        "vlr_count": (small, "<I", 100, 2**32 - 1),
        # issue 15.2: 10**8 points declared: 3 GB allocated, 1000 read silently
        "count_legacy": (las12, "<I", 107, 10**8),
        "count_14": (las, "<Q", 247, 10**8),
        "count_laz": (laz, "<Q", 247, 10**8),
        # number_of_evlrs = 2**32 - 1: ran for ever too
        "evlr_count": (with_evlr, "<I", 243, 2**32 - 1),
    }
    cases, paths = [], {}
    for case, (data, fmt, pos, value) in files.items():
        paths[case] = folder / f"{case}{'.laz' if data is laz else '.las'}"
        paths[case].write_bytes(_put(data, fmt, pos, value))
        cases += [(f"{case}-{r}", str(paths[case]), r) for r in CHILD_READERS]
    return paths, _in_child(cases)


@pytest.mark.parametrize("reader", CHILD_READERS)
@pytest.mark.parametrize(
    ("case", "match"),
    [
        ("chunk_size", "invalid laszip VLR: chunk size 4294901760 points"),
        ("no_items", "invalid laszip VLR: 0 items"),
        (
            "table_offset",
            "the chunk table that indexes them, at byte 4611686018427387904",
        ),
        ("layer_size", r"corrupt LAZ chunk 1 at byte \d+: its layers take"),
        ("vlr_count", "declares 4294967295 VLRs, but only 1 fit"),
        (
            "count_legacy",
            "truncated: the header declares 100000000 points, the file holds 1000 ",
        ),
        (
            "count_14",
            "truncated: the header declares 100000000 points, the file holds 1000 ",
        ),
        ("count_laz", "declares 100000000 points, the chunk table indexes 100000 "),
        ("evlr_count", "declares 4294967295 EVLRs, but only 1 fit"),
    ],
)
def test_no_crash_hang_or_allocation(dangerous, case, match, reader):
    paths, results = dangerous
    outcome, message = results[f"{case}-{reader}"]
    assert outcome == "PointCloudFileError", (outcome, message)
    assert message.startswith(f"{paths[case]}: cannot read as LAS/LAZ: "), message
    assert re.search(match, message), message


# --- silent short reads and header lies: in this process --------------------


@pytest.mark.parametrize(("point_format", "version"), [(3, "1.2"), (6, "1.4")])
def test_a_file_cut_at_a_record_boundary(tmp_path, point_format, version):
    # issue 15.2: 500 of 1000 declared points were read without a word
    path = tmp_path / "cut.las"
    data = _write(path, n=1000, point_format=point_format, version=version)
    record = struct.unpack_from("<H", data, 105)[0]
    path.write_bytes(data[: _offset(data) + 500 * record])
    match = (
        "truncated: the header declares 1000 points, the file holds 500 "
        rf"\({500 * record} bytes of {record}-byte records"
    )
    for reader in READERS:
        _expect(path, match, reader)
    # a longer file is fine
    path.write_bytes(data + b"\0" * 100)
    assert len(_read(path)[0]) == 1000


def test_iter_points_from_a_header_only_file(tmp_path):
    # issue 15.2: iter_points yielded 0 points (and tiled segmentation
    # segmented part of a scan) where its docstring promised an error
    path = tmp_path / "header.las"
    data = _write(path, n=1000)
    path.write_bytes(data[: _offset(data)])
    _expect(path, "declares 1000 points, the file holds 0 ", _iter)
    # no point declared: an empty iteration, not an error
    empty = tmp_path / "empty.las"
    path.write_bytes(_put(data[: _offset(data)], "<Q", 247, 0))
    empty.write_bytes(path.read_bytes())
    assert list(iter_points(empty)) == []


def test_a_laz_file_truncated_mid_stream(tmp_path):
    # layered chunks (point format 6): the complete chunks are counted
    path = tmp_path / "cut.laz"
    data = _write(path, n=60_000)
    path.write_bytes(data[: int(len(data) * 0.9)])
    for reader in READERS:
        _expect(
            path,
            "truncated or corrupt LAZ: the header declares 60000 points, the file "
            r"holds 50000 \(its first 1 complete chunks\); the chunk table",
            reader,
        )
    # point-wise chunks (point format 3): the chunk table is needed to count
    path = tmp_path / "cut3.laz"
    data = _write(path, n=60_000, point_format=3, version="1.2")
    path.write_bytes(data[: int(len(data) * 0.9)])
    _expect(path, "truncated or corrupt LAZ: the header declares 60000 points; ", _read)


def test_laz_with_a_header_count_beyond_its_chunks(tmp_path):
    path = tmp_path / "count.laz"
    data = _write(path, n=1000)
    path.write_bytes(_put(data, "<Q", 247, 60_000))
    _expect(path, "declares 60000 points, the chunk table indexes 50000 ", _read)


def test_laszip_vlr_checks(tmp_path):
    path = tmp_path / "v.laz"
    data = _write(path, n=100)
    vlr = _laszip(data)
    cases = [
        ("<H", vlr, 1, "compressor 1 .pointwise, not chunked"),
        ("<H", vlr, 9, "unknown compressor 9"),
        ("<H", vlr + 2, 1, "unknown coder 1"),
        ("<B", vlr + 4, 7, "unknown LASzip version 7"),
        ("<I", vlr + 12, 0, "chunk size 0 points"),
        ("<I", vlr + 12, 2**24 + 1, "chunk size 16777217 points"),
        ("<H", vlr + 32, 11, "11 items"),
        ("<H", vlr + 34, 6, r"items \[6, 14\] do not match point format 6"),
        ("<H", vlr + 36, 31, "item 10 of 31 bytes"),
        ("<H", vlr + 42, 5, "item 14 of 5 bytes .expected 4"),
    ]
    for fmt, pos, value, match in cases:
        path.write_bytes(_put(data, fmt, pos, value))
        _expect(path, "invalid laszip VLR: " + match, _read)
    # fixed-size chunks read as variable ones: the chunk table makes no sense
    path.write_bytes(_put(data, "<I", vlr + 12, 0xFFFFFFFF))
    _expect(path, "corrupt LAZ chunk 1 at byte", _read)


def _variable_laz(path, n=1000, sizes=(300, 500, 200)):
    """A LAZ file of variable-size chunks (laspy does not write them): the
    points of a LAS file compressed with lazrs, chunk by chunk."""
    import lazrs

    data = _write(path.with_suffix(".las"), n=n)
    offset = _offset(data)
    record = struct.unpack_from("<H", data, 105)[0]
    vlr = lazrs.LazVlr.new_for_compression(6, record - 30, True)
    body = vlr.record_data()
    head = bytearray(data[:offset])
    head += struct.pack("<H16sHH32s", 0, b"laszip encoded", 22204, len(body), b"")
    head += body
    struct.pack_into("<I", head, 96, len(head))
    struct.pack_into("<I", head, 100, struct.unpack_from("<I", head, 100)[0] + 1)
    head[104] |= 0x80
    out = io.BytesIO()
    out.write(bytes(head))
    compressor = lazrs.LasZipCompressor(out, vlr)
    compressor.reserve_offset_to_chunk_table()
    start = offset
    for size in sizes:
        compressor.compress_many(bytes(data[start : start + size * record]))
        compressor.finish_current_chunk()
        start += size * record
    compressor.done()
    path.write_bytes(out.getvalue())
    return laspy.read(str(path.with_suffix(".las")))


def test_variable_size_chunks(tmp_path):
    path = tmp_path / "variable.laz"
    las = _variable_laz(path)
    points, fields = _read(path)
    assert np.array_equal(points[:, 0], las.x)
    assert np.array_equal(fields["reflectance"], las.reflectance)
    assert _iter(path) == 1000 == read_las_extent(path).n_points
    data = path.read_bytes()
    path.write_bytes(_put(data, "<Q", 247, 1001))
    _expect(path, "declares 1001 points, the chunk table indexes 1000 ", _read)


def test_header_checks(tmp_path):
    path = tmp_path / "h.las"
    cases = [
        ("<H", 94, 300, "the header size is 300 bytes .LAS 1.4 needs 375"),
        ("<H", 94, 60000, "the header size is 60000 bytes"),
        ("<I", 96, 10**6, "the point data starts at byte 1000000, outside"),
        ("<I", 96, 200, "the point data starts at byte 200, outside"),
        ("<B", 104, 12, "unknown point format 12"),
        ("<H", 105, 20, "point records of 20 bytes, shorter than point format 6"),
        ("<I", 107, 7, r"point counts disagree: 7 \(legacy field\) and 10"),
        ("<d", 131, float("nan"), "invalid coordinate scales"),
        ("<d", 139, 0.0, "invalid coordinate scales"),
        ("<d", 155, float("inf"), "invalid coordinate scales"),
        ("<B", 24, 2, "unknown LAS version 2.4"),
        ("<I", 100, 3, "declares 3 VLRs, but only 1 fit"),
        ("<H", 375 + 20, 60000, r"VLR 1 of 1 .* runs past the end of the point data"),
        ("<Q", 247, 11, "the 11 points declared .* run into the EVLRs"),
        ("<Q", 235, 10, "the EVLRs start at byte 10, before the point data"),
    ]
    data = _write(path, n=10, evlr=True)
    for fmt, pos, value, match in cases:
        path.write_bytes(_put(data, fmt, pos, value))
        for reader in READERS:
            _expect(path, match, reader)
    path.write_bytes(data[:100])
    _expect(path, "100 bytes, too short for a LAS header", _read)
    path.write_bytes(b"LASX" + data[4:])
    _expect(path, "no 'LASF' signature", _read)
    path.write_bytes(data[:-10])  # cut inside the EVLR
    _expect(path, r"EVLR 1 of 1 .* runs past the end of the file", _read)


class _FakePanic(BaseException):
    """What lazrs raises when the Rust decoder panics (pyo3's PanicException
    is a BaseException, not an Exception)."""


def test_decoder_panics_become_the_librarys_error(tmp_path, monkeypatch):
    path = tmp_path / "p.laz"
    _write(path, n=100)

    def panic(self, n):
        raise _FakePanic("attempt to calculate the remainder with a divisor of zero")

    monkeypatch.setattr(laspy.LasReader, "read_points", panic)
    message = _expect(path, "the LAZ decoder failed", _read)
    assert "_FakePanic: attempt to calculate the remainder" in message
    _expect(path, "the LAZ decoder failed", _iter)

    def memory(self, n):
        raise MemoryError

    monkeypatch.setattr(laspy.LasReader, "read_points", memory)
    _expect(path, "not enough memory to decode the points", _read)

    def interrupt(self, n):
        raise KeyboardInterrupt

    monkeypatch.setattr(laspy.LasReader, "read_points", interrupt)
    with pytest.raises(KeyboardInterrupt):
        _read(path)


def test_valid_files_still_read(tmp_path):
    for point_format, version, ext in [(3, "1.2", ".laz"), (6, "1.4", ".las")]:
        path = tmp_path / f"ok{ext}"
        evlr = version == "1.4"
        _write(path, n=70_000, point_format=point_format, version=version, evlr=evlr)
        las = laspy.read(str(path))
        points, fields = _read(path)
        assert len(points) == 70_000 == read_las_extent(path).n_points
        assert np.array_equal(fields["reflectance"], las.reflectance)
        assert np.array_equal(points[:, 0], las.x)
        assert _iter(path) == 70_000


# --- a seeded mutation fuzz ---------------------------------------------------

FUZZ = textwrap.dedent(
    """
    import json, os, resource, signal, struct, sys
    import numpy as np
    from skpcd.exceptions import PointCloudFileError
    from skpcd.io import iter_points, read_las_extent, read_point_cloud

    folder, seed, n_mutations = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    pages = int(open("/proc/self/statm").read().split()[0])
    limit = pages * resource.getpagesize() + (1 << 30)
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))

    def hang(*_):
        raise TimeoutError("no answer within 20 s")

    signal.signal(signal.SIGALRM, hang)
    bases = sorted(n for n in os.listdir(folder) if n.startswith("base"))
    rng = np.random.default_rng(seed)
    EXTREMES = [0, 1, 0xFF, 0xFFFF, 0x7FFFFFFF, 0x80000000, 0xFFFFFFFF]

    def declared(data):
        if len(data) < 255 or data[:4] != b"LASF":
            return None
        if data[25] >= 4:
            return struct.unpack_from("<Q", data, 247)[0]
        return struct.unpack_from("<I", data, 107)[0]

    def mutate(data):
        data = bytearray(data)
        offset = struct.unpack_from("<I", data, 96)[0]
        kind = rng.choice(["byte", "field", "cut", "tail"], p=[0.45, 0.35, 0.1, 0.1])
        if kind == "cut":
            return data[: int(rng.integers(0, len(data)))], "cut"
        if kind == "tail":
            return data + bytes(rng.integers(0, 256, 64, dtype=np.uint8)), "tail"
        what = []
        for _ in range(int(rng.integers(1, 4))):
            region = rng.choice(["structure", "end", "anywhere"], p=[0.7, 0.1, 0.2])
            if region == "structure":  # header, VLRs, chunk table offset, chunk header
                pos = int(rng.integers(0, min(offset + 120, len(data))))
            elif region == "end":  # the LAZ chunk table, the EVLRs
                pos = int(rng.integers(max(len(data) - 64, 0), len(data)))
            else:
                pos = int(rng.integers(0, len(data)))
            if kind == "byte":
                data[pos] = int(rng.integers(0, 256))
            elif pos + 4 <= len(data):
                data[pos : pos + 4] = struct.pack("<I", int(rng.choice(EXTREMES)))
            what.append(pos)
        return data, f"{kind} at {what}"

    for k in range(n_mutations):
        base = bases[k % len(bases)]
        with open(os.path.join(folder, base), "rb") as f:
            data, what = mutate(f.read())
        path = os.path.join(folder, "m" + base)
        with open(path, "wb") as f:
            f.write(data)
        print(json.dumps({"k": k, "mutation": f"{base}: {what}"}), flush=True)
        problems = []
        signal.alarm(20)
        try:
            for name, reader in [
                ("read", lambda: len(read_point_cloud(path, nonfinite="keep"))),
                ("iter", lambda: sum(len(c) for c in iter_points(path, chunk_size=97))),
                ("extent", lambda: read_las_extent(path).n_points),
            ]:
                try:
                    n = reader()
                except PointCloudFileError as exc:
                    if not str(exc).startswith(path + ": "):
                        problems.append(f"{name}: error not naming the file: {exc}")
                    continue
                if n != declared(data):
                    problems.append(f"{name}: {n} points, header {declared(data)}")
        except BaseException as exc:
            problems.append(f"{type(exc).__name__}: {str(exc)[:200]}")
        signal.alarm(0)
        if problems:
            print(json.dumps({"k": k, "problems": problems}), flush=True)
    print(json.dumps({"done": n_mutations}), flush=True)
    """
)


def test_mutation_fuzz(tmp_path):
    _write(tmp_path / "base12.las", n=200, point_format=3, version="1.2")
    _write(tmp_path / "base14.las", n=200, evlr=True)
    _write(tmp_path / "base3.laz", n=200, point_format=3, version="1.2")
    _write(tmp_path / "base6.laz", n=200)
    _write(tmp_path / "base7.laz", n=200, point_format=7, version="1.4", evlr=True)
    proc = subprocess.run(
        [sys.executable, "-c", FUZZ, str(tmp_path), "20150415", "300"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    records = [json.loads(line) for line in proc.stdout.splitlines()]
    mutations = {r["k"]: r["mutation"] for r in records if "mutation" in r}
    failures = [(mutations[r["k"]], r["problems"]) for r in records if "problems" in r]
    if not records or "done" not in records[-1]:
        last = records[-1]["mutation"] if records else "(none)"
        pytest.fail(
            f"the fuzz process died (rc {proc.returncode}) on {last}: "
            f"{proc.stderr[-500:]}"
        )
    assert not failures, failures[:5]
