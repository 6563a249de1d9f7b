"""Tasks over the tiles of a scene: where each tile is read and computed.

:func:`map_tiles` maps a pass of the tiled segmentation over the tiles, in
this process or as the tasks of a joblib backend (threads, processes, a
Dask cluster), one tile per running task in flight. Tasks that see this
machine's files (:func:`shares_files`: joblib's own backends, a Dask
cluster whose workers all have an address here) read their tile
themselves, from its spill file or from the COPC file the scene is read
from; others get the prepared tile shipped.
"""

import collections
import secrets
import socket
import typing

import numpy as np
from joblib import cpu_count, effective_n_jobs
from sklearn.utils.parallel import Parallel, delayed

from skpcd.utils._memory import heap_for_arrays, release_free_memory
from skpcd.utils._parallel import (
    chosen_backend,
    dask_hosts,
    effective_threads,
    run_batch,
)
from skpcd.utils._progress import steps

__all__ = ["map_tiles", "shares_files"]


# Each pass (ground, eps, clusters) maps a function over the tiles in two
# steps: ``prepare(xyz, index, ground, tile, *pargs)`` cuts from the buffered
# tile what the pass needs, returning ``(args, info)``, and
# ``compute(*args, *cargs, n_threads)`` does the work; ``info`` (scan
# indices) tells the driver where the result goes. In this process, or when
# the tasks of a joblib backend see this machine's files, each task reads
# its tile from the spill file and prepares it itself (the driver only
# sends the tile's name); else the driver reads and prepares the tile and
# ships the prepared arrays.


class _TileRef(typing.NamedTuple):
    """A tile for a task to read itself: its reader (the spill file, or the
    nodes of a COPC file), the scene's token (file, content) that proves
    the task sees this machine's files, and the scene's ground flags file
    (None when the pass does not need it)."""

    reader: typing.Any
    token: tuple
    ground: str | None


def _read_ref(ref):
    """``(xyz, index, ground)`` of a tile reference, or None when the token
    file is not there with the same content (another machine's files)."""
    try:
        with open(ref.token[0], encoding="ascii") as f:
            if f.read() != ref.token[1]:
                return None
        xyz, index = ref.reader.load()
        ground = None
        if ref.ground is not None:
            ground = np.asarray(np.load(ref.ground, mmap_mode="r")[index])
    except OSError:
        return None
    return xyz, index, ground


def _tile_call(job, n_threads):
    """One tile of :func:`map_tiles`: ``(info, result)``; ``info`` is None
    for a shipped tile (the driver has it), and None is returned for a
    tile reference the task cannot read."""
    if heap_for_arrays():
        try:
            return _tile_call_inner(job, n_threads)
        finally:
            release_free_memory()
    return _tile_call_inner(job, n_threads)


def _tile_call_inner(job, n_threads):
    tile, t, prepare, pargs, compute, cargs = job
    if isinstance(tile, _TileRef):
        data = _read_ref(tile)
        if data is None:
            return None
        tile, info = prepare(*data, t, *pargs)
        return info, compute(*tile, *cargs, n_threads)
    return None, compute(*tile, *cargs, n_threads)


_LOCAL_BACKENDS = ("ThreadingBackend", "LokyBackend", "MultiprocessingBackend")


def _local_hosts():
    """Names and addresses of this machine."""
    names = {"127.0.0.1", "localhost", "::1", "0.0.0.0"}
    try:
        host = socket.gethostname()
        names.add(host)
        names.update(socket.gethostbyname_ex(host)[2])
    except OSError:  # pragma: no cover - no name resolution
        pass
    return names


def shares_files(backend):
    """Whether the tasks of a joblib ``backend`` run on this machine, so that
    they can read the tile files: joblib's own backends (threads and
    processes here), and Dask when every worker has an address of this
    machine (a ``LocalCluster``). Any other backend gets shipped tiles."""
    if type(backend).__name__ in _LOCAL_BACKENDS:
        return True
    hosts = dask_hosts(backend)
    return bool(hosts) and set(hosts) <= _local_hosts()


def _scene_token(scene):
    """``(file, content)`` of a random token written in the scene's folder."""
    token = getattr(scene, "_token", None)
    if token is None:
        token = (str(scene.folder / "token"), secrets.token_hex(16))
        with open(token[0], "w", encoding="ascii") as f:
            f.write(token[1])
        scene._token = token
    return token


def map_tiles(scene, tiles, prepare, pargs, compute, cargs, n_jobs, ground=None):
    """``(info, compute(*args, *cargs, n_threads))`` for each tile of
    ``tiles``, ``(args, info) = prepare(xyz, index, ground[index], tile,
    *pargs)``, in order, lazily (one tile in memory at a time, or one per
    running task).

    As :func:`skpcd.utils._parallel.map_batches`, of which this is the
    streaming form for tiles: in this process with ``n_jobs`` threads per
    call (the freed heap given back to the system after each tile, see
    :func:`~skpcd.utils._memory.release_free_memory`) unless a joblib
    backend was chosen (``parallel_config``); then
    through :class:`sklearn.utils.parallel.Parallel` (on a Dask cluster
    inside ``parallel_config(backend="dask")``), ``n_jobs`` tiles at once
    (None: the context's), each with the cores left to its task.

    On a backend whose tasks run on this machine (:func:`shares_files`),
    a task gets the tile's name and reads and prepares the tile itself,
    and up to two tiles per running task are sent ahead; the driver reads
    nothing. A task that does not find the scene's token (a worker with
    other files under the same name) returns None: that tile, and those
    already sent, are then computed here, and the following ones shipped.
    Elsewhere the driver reads and prepares each tile and ships its arrays,
    one tile per running task in flight. ``ground`` is ``(flags, path)``:
    the scan's ground flags and the file they are mapped from (flushed
    before the tasks read it), or None.
    """

    flags, flags_path = (None, None) if ground is None else ground
    name = compute.__name__.strip("_").removesuffix("_tile")
    tiles = steps(tiles, f"tiles ({name})")  # a bar on the command's terminal

    def here(t, n_threads):
        xyz, index = scene.load(t)
        g = None if flags is None else np.asarray(flags[index])
        args, info = prepare(xyz, index, g, t, *pargs)
        return info, compute(*args, *cargs, n_threads)

    backend = chosen_backend()
    if backend is None:
        for t in tiles:
            out = here(t, effective_threads(n_jobs))
            # the tile's temporaries, freed, back to the system: the C heap
            # would keep them, and the next tile's land among them
            release_free_memory()
            yield out
        return
    n_tasks = max(1, int(effective_n_jobs(n_jobs)))
    inner = getattr(backend, "inner_max_num_threads", None)
    n_threads = inner or max(1, cpu_count() // n_tasks)
    hosts = None if inner else dask_hosts(backend)
    shared = [shares_files(backend)]
    if shared[0]:
        token = _scene_token(scene)
        if flags is not None:
            flags.flush()
    pending = collections.deque()

    def jobs():
        for t in tiles:
            if shared[0]:
                tile = _TileRef(scene.tile_reader(t), token, flags_path)
                job = (tile, t, prepare, pargs, compute, cargs)
                pending.append((t, None))
            else:
                xyz, index = scene.load(t)
                g = None if flags is None else np.asarray(flags[index])
                tile, info = prepare(xyz, index, g, t, *pargs)
                del xyz, index, g
                job = (tile, t, None, (), compute, cargs)
                pending.append((t, info))
            yield delayed(run_batch)(_tile_call, job, n_threads, hosts)

    pre_dispatch = "2 * n_jobs" if shared[0] else "n_jobs"
    for out in Parallel(
        n_jobs=n_jobs, batch_size=1, pre_dispatch=pre_dispatch, return_as="generator"
    )(jobs()):
        t, info = pending.popleft()
        if out is None:  # the task did not see our files: here, then ship
            shared[0] = False
            yield here(t, effective_threads(n_jobs))
            continue
        mine, result = out
        yield (info if mine is None else mine), result
