"""COPC files: the octree index read and checked, tiles read from the octree
by their bounds (the same points as the spilled tiles, so the same
segmentation, locally and on Dask), and labelled copies that drop the
octree's records. On a real COPC file (tests/data/copc, see its README)."""

import struct
from pathlib import Path

import joblib
import laspy
import numpy as np
import pytest

import skpcd.segmentation.tiling._dispatch as dispatch
import skpcd.segmentation.tiling._spill as spill
from skpcd.exceptions import PointCloudFileError
from skpcd.io import read_point_cloud, write_labelled_scan
from skpcd.io._copc import is_copc, read_copc_index, read_nodes
from skpcd.io._las_reader import read_vlr_records
from skpcd.io._las_structure import checked_layout
from skpcd.segmentation import GroundFilter, segment_scene
from skpcd.segmentation.tiling._octree import OctreeScene, OctreeTile

COPC = Path(__file__).parents[1] / "data" / "copc" / "simple.copc.laz"
N_POINTS = 1065

# the settings of the tiled segmentations compared below (the file is a
# sparse aerial sample: points about 60 m apart, 3.4 km x 4.6 km)
SETTINGS = {
    "dbscan": {"ground": None, "eps": 60.0, "min_cluster_size": 5},
    "euclidean": {
        "ground": None,
        "method": "euclidean",
        "eps": 40.0,
        "min_cluster_size": 3,
    },
    "smrf": {
        "ground": GroundFilter(cell=30.0, window=300.0, threshold=2.0, slope=0.3),
        "eps": 60.0,
        "min_cluster_size": 5,
    },
}


def _spilled(monkeypatch):
    """Within it, a COPC file is read as any LAZ file (the spill path)."""
    monkeypatch.setattr(spill, "is_copc", lambda source: False)


def _same_scenes(a, b):
    assert a.grid == b.grid and a.n_points == b.n_points
    for name in ("mins", "maxs", "counts"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert np.array_equal(a.owned_counts(), b.owned_counts())
    for t in range(a.grid.n_tiles):
        xa, ia = a.load(t)
        xb, ib = b.load(t)
        assert xa.dtype == xb.dtype == np.float64
        assert np.array_equal(xa, xb) and np.array_equal(ia, ib), t


def _patched(tmp_path, changes, name="bad.copc.laz"):
    """A copy of the COPC file with ``{byte: bytes}`` written over it."""
    data = bytearray(COPC.read_bytes())
    for at, raw in changes.items():
        data[at : at + len(raw)] = raw
    path = tmp_path / name
    path.write_bytes(bytes(data))
    return path


def _entry(k):
    """First byte of entry ``k`` of the root hierarchy page."""
    info = checked_layout(COPC, points=False).vlrs[0][2]
    (root,) = struct.unpack("<Q", COPC.read_bytes()[info + 40 : info + 48])
    return root + 32 * k


# --- the index --------------------------------------------------------------


def test_nodes_read_as_read_point_cloud_reads_the_file():
    index = read_copc_index(COPC)
    assert index.n_points == N_POINTS == index.count.sum()
    # file order: nodes by offset, numbered by their cumulative counts
    assert np.all(np.diff(index.offset) > 0)
    assert np.array_equal(index.start[1:], np.cumsum(index.count)[:-1])
    parts = [xyz for _, xyz in read_nodes(index, range(len(index.count)))]
    assert np.array_equal(np.concatenate(parts), read_point_cloud(COPC))


def test_a_copc_file_is_known_by_its_info_vlr_not_its_name(tmp_path):
    plain = tmp_path / "plain.copc.laz"
    write_labelled_scan(
        COPC, plain, segment=np.zeros(N_POINTS, int),
        class_index=np.zeros(N_POINTS, int), class_names=["a"],
    )  # fmt: skip
    renamed = tmp_path / "scan.laz"
    renamed.write_bytes(COPC.read_bytes())
    assert is_copc(COPC) and is_copc(renamed)
    assert not is_copc(plain)
    assert not is_copc(tmp_path / "missing.copc.laz")
    with spill.tile_scene(renamed, 1000.0) as scene:
        assert isinstance(scene, OctreeScene)
    with spill.tile_scene(plain, 1000.0) as scene:
        assert not isinstance(scene, OctreeScene)


# --- tiles from the octree ---------------------------------------------------


@pytest.mark.parametrize(
    "size, buffer", [(700.0, 50.0), (250.0, 10.0), (400.0, 450.0), (9000.0, 0.0)]
)
def test_octree_tiles_are_the_spilled_tiles(size, buffer, monkeypatch):
    with spill.tile_scene(COPC, size, buffer=buffer) as octree:
        assert isinstance(octree, OctreeScene)
        # the folder holds no tile files
        assert list(octree.folder.iterdir()) == []
        with monkeypatch.context() as m:
            _spilled(m)
            with spill.tile_scene(COPC, size, buffer=buffer) as spilled:
                assert not isinstance(spilled, OctreeScene)
                _same_scenes(octree, spilled)
        # only the nodes near a tile are read for it
        reader = octree.tile_reader(0)
        assert isinstance(reader, OctreeTile)
        if octree.grid.n_tiles > 4:
            assert len(reader.index.count) < len(octree.index.count)
    assert not octree.folder.exists()


def test_bounds_are_the_points_not_the_header(tmp_path, monkeypatch):
    points = read_point_cloud(COPC)
    header = laspy.open(COPC).header
    # this file's header does not give the points' highest x
    assert header.maxs[0] != points[:, 0].max()
    with spill.tile_scene(COPC, 700.0) as scene:
        assert np.array_equal(scene.mins, points.min(axis=0))
        assert np.array_equal(scene.maxs, points.max(axis=0))
    # a header whose bounds leave points out: tiled on the points' bounds,
    # as the spill path does
    lowered = header.mins[0] + 0.5 * (header.maxs[0] - header.mins[0])
    path = _patched(tmp_path, {179: struct.pack("<d", lowered)})
    with spill.tile_scene(path, 700.0, buffer=50.0) as octree:
        assert octree.grid.shape[0] == int(np.ceil(np.ptp(points[:, 0]) / 700))
        with monkeypatch.context() as m:
            _spilled(m)
            with spill.tile_scene(path, 700.0, buffer=50.0) as spilled:
                _same_scenes(octree, spilled)


@pytest.mark.parametrize("name", sorted(SETTINGS))
def test_segment_scene_on_copc_is_the_spill_path_and_in_memory(name, monkeypatch):
    kwargs = dict(SETTINGS[name], structures=False)
    octree = segment_scene(COPC, tile_size=700.0, **kwargs)
    with monkeypatch.context() as m:
        _spilled(m)
        spilled = segment_scene(COPC, tile_size=700.0, **kwargs)
    whole = segment_scene(read_point_cloud(COPC), **kwargs)
    assert octree.labels.max() >= 0  # segments, not only noise
    for other in (spilled, whole):
        assert np.array_equal(octree.labels, other.labels)
        assert np.array_equal(octree.ground, other.ground)
        assert octree.eps == other.eps
    if name == "smrf":
        assert 0 < octree.ground.sum() < N_POINTS


def test_tasks_read_their_tile_from_the_copc_file(monkeypatch):
    kwargs = dict(SETTINGS["dbscan"], structures=False)
    local = segment_scene(COPC, tile_size=400.0, **kwargs)
    readers = []
    read_ref = dispatch._read_ref

    def recording(ref):
        readers.append(ref.reader)
        return read_ref(ref)

    monkeypatch.setattr(dispatch, "_read_ref", recording)
    with joblib.parallel_config(backend="threading", n_jobs=2):
        tiled = segment_scene(COPC, tile_size=400.0, **kwargs)
    assert readers and all(isinstance(r, OctreeTile) for r in readers)
    assert np.array_equal(tiled.labels, local.labels)


@pytest.mark.parametrize("where", ["shared", "shipped"])
def test_dask_cluster_gives_the_local_result(dask_client, where, monkeypatch):
    from distributed import get_task_stream

    kwargs = dict(SETTINGS["smrf"], structures=False)
    local = segment_scene(COPC, tile_size=700.0, **kwargs)
    if where == "shipped":  # workers elsewhere: the driver reads the tiles
        monkeypatch.setattr(dispatch, "shares_files", lambda backend: False)
    with get_task_stream(dask_client) as stream:
        with joblib.parallel_config(backend="dask"):
            tiled = segment_scene(COPC, tile_size=700.0, **kwargs)
    workers = {t["worker"] for t in stream.data if "run_batch" in str(t["key"])}
    assert workers and workers <= set(dask_client.scheduler_info()["workers"])
    assert np.array_equal(tiled.labels, local.labels)
    assert np.array_equal(tiled.ground, local.ground)


# --- a labelled copy ----------------------------------------------------------


def test_a_labelled_copy_drops_the_octree_and_keeps_the_crs(tmp_path):
    out = tmp_path / "labelled.laz"
    segment = np.arange(N_POINTS) % 7
    write_labelled_scan(
        COPC, out, segment=segment, class_index=np.zeros(N_POINTS, int),
        class_names=["a"], ground=segment == 0,
    )  # fmt: skip
    source = {(u, r): d for u, r, d in read_vlr_records(COPC)}
    copy = {(u, r): d for u, r, d in read_vlr_records(out)}
    assert ("copc", 1) in source and ("copc", 1000) in source
    assert not any(user == "copc" for user, _ in copy)
    # the CRS (WKT) kept; laspy ends the string with a null byte
    wkt = source[("LASF_Projection", 2112)]
    assert copy[("LASF_Projection", 2112)].rstrip(b"\0") == wkt.rstrip(b"\0")
    assert not is_copc(out)
    with pytest.raises(laspy.errors.LaspyException, match="not a valid COPC"):
        laspy.CopcReader.open(out)
    las = laspy.read(out)
    assert np.array_equal(las["segment"], segment)
    assert np.array_equal(read_point_cloud(out), read_point_cloud(COPC))


# --- bad files ----------------------------------------------------------------


def _info_at():
    return checked_layout(COPC, points=False).vlrs[0][2]


@pytest.mark.parametrize(
    "change, match",
    [
        # the root page past the end of the file
        (lambda: {_info_at() + 40: struct.pack("<Q", 10**9)}, "page of .* within"),
        # a page size that is not whole entries
        (lambda: {_info_at() + 48: struct.pack("<Q", 33)}, "page of 33 bytes"),
        # a node with one point more than its chunk
        (lambda: {_entry(3) + 28: struct.pack("<i", 18)}, "hold 1066 points"),
        # two nodes whose counts do not match their chunks (sum unchanged)
        (
            lambda: {
                _entry(0) + 28: struct.pack("<i", 1),
                _entry(1) + 28: struct.pack("<i", 24 + 19 - 1),
            },
            "does not index the LAZ chunks",
        ),
        # a node pointing into the middle of a chunk
        (lambda: {_entry(5) + 16: struct.pack("<Q", 2000)}, "does not index"),
        # a page that refers to itself
        (
            lambda: {_entry(2) + 16: struct.pack("<Qii", _entry(0), 2080, -1)},
            "reached twice",
        ),
        (lambda: {_entry(4): struct.pack("<i", 99)}, "invalid node key"),
        (lambda: {_entry(4) + 28: struct.pack("<i", -5)}, "-5 points"),
        (lambda: {_info_at() + 24: struct.pack("<d", -1.0)}, "halfsize -1.0"),
    ],
)
def test_a_corrupt_hierarchy_is_a_one_line_error(tmp_path, change, match):
    path = _patched(tmp_path, change())
    with pytest.raises(PointCloudFileError, match=match) as info:
        spill.tile_scene(path, 700.0)
    message = str(info.value)
    assert message.startswith(str(path)) and "\n" not in message


def test_entries_are_what_the_tests_above_assume():
    index = read_copc_index(COPC)
    raw = COPC.read_bytes()
    entries = [struct.unpack_from("<4iQii", raw, _entry(k)) for k in range(6)]
    by_offset = dict(zip(index.offset.tolist(), index.count.tolist(), strict=True))
    assert all(by_offset[e[4]] == e[6] for e in entries)
    assert [e[6] for e in entries[:4]] == [24, 19, 16, 17]


def test_truncated_and_corrupt_points(tmp_path):
    raw = COPC.read_bytes()
    cut = tmp_path / "cut.copc.laz"
    cut.write_bytes(raw[: len(raw) // 2])
    with pytest.raises(PointCloudFileError, match=str(cut)):
        segment_scene(cut, tile_size=700.0, structures=False, **SETTINGS["dbscan"])
    # the x, y layer of the largest node overwritten: its points land
    # outside its cube
    index = read_copc_index(COPC)
    k = int(np.argmax(index.nbytes))
    head = index.record_length + 4 + 4 * 10  # first point, count, 10 layer sizes
    at = int(index.offset[k]) + head + 4
    path = _patched(tmp_path, {at: b"\xff" * 40})
    with pytest.raises(PointCloudFileError, match="outside its cube"):
        spill.tile_scene(path, 700.0)


def test_a_copc_scan_not_in_metres_is_spilled_and_gives_the_in_memory_result():
    # the scaling page: with unit != 1 the octree is not used, the file is
    # spilled as any LAZ file, coordinates scaled as they are read
    kwargs = dict(SETTINGS["dbscan"], structures=False, unit=0.5)
    kwargs["eps"] = 120.0  # in the file's units: 60 after scaling
    tiled = segment_scene(COPC, tile_size=1400.0, **kwargs)
    whole = segment_scene(read_point_cloud(COPC), **kwargs)
    assert tiled.labels.max() >= 0
    assert np.array_equal(tiled.labels, whole.labels)
    assert tiled.eps == whole.eps == 120.0 and tiled.unit == 0.5
    metres = segment_scene(
        read_point_cloud(COPC) * 0.5, **dict(kwargs, unit=1.0, eps=60.0)
    )
    assert np.array_equal(whole.labels, metres.labels)
