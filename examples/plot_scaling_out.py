"""
Descriptors on a Dask cluster
=============================

skpcd's descriptor transformers cut a list of clouds into batches of whole clouds;
inside ``joblib.parallel_config(backend="dask")`` the batches run on the workers of a
``dask.distributed`` cluster, and the result is the same, bit for bit, as in this
process. Here the cluster is a :class:`~distributed.LocalCluster` of two worker
processes on this machine; pointed at a scheduler's address (``Client("tcp://...")``),
the same code runs on many machines. See the user guide's :ref:`scaling` page.

The clouds are 100 DALES objects where ``SKPCD_DALES_DIR`` names their folder, and
100 synthetic objects of :func:`skpcd.datasets.make_urban_objects` otherwise (the
output says which); the timings are those of the machine that built this page.
"""

import logging
import time

import joblib
import matplotlib.pyplot as plt
import numpy as np
from dask.distributed import Client, LocalCluster, get_task_stream

from skpcd.datasets import load_dales_objects
from skpcd.features import PFHTransformer
from skpcd.utils import batch_config

# The DALES objects where SKPCD_DALES_DIR names their folder, else synthetic objects
# of make_urban_objects (20 per class); ``objects.folder`` is None for the latter.
objects = load_dales_objects(synthetic_if_missing=True, n_per_class=20)
if objects.folder is not None:
    data = f"DALES objects ({len(objects.data)} real aerial objects)"
else:
    data = f"synthetic make_urban_objects ({len(objects.data)}; DALES unavailable)"
print(f"data: {data}")
clouds = objects.data[:100]
print(f"{len(clouds)} of them, {sum(map(len, clouds))} points")

pfh = PFHTransformer(n_neighbors=10, pooling="mean", n_jobs=2)

# %%
# In this process first: no joblib backend is chosen, so the kernels run on
# ``n_jobs`` threads here (this also compiles them, or loads them from numba's
# cache, which the workers then reuse).
start = time.perf_counter()
local = pfh.fit_transform(clouds)
print(f"local: {local.shape} in {time.perf_counter() - start:.2f} s")

# %%
# The same call on two worker processes of one thread each. Each batch's kernels
# get the cores of the machine divided by the worker threads on it (here 1), so
# the two workers do not oversubscribe the cores. Batches are at most a million
# points by default; :func:`~skpcd.utils.batch_config` makes them smaller here, so
# that each worker gets several. The task stream records where every batch ran.
with (
    LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        processes=True,
        dashboard_address=":0",  # any free port
        silence_logs=logging.ERROR,
    ) as cluster,
    Client(cluster) as client,
):
    # load the kernels in the workers (from numba's cache)
    client.run(PFHTransformer(n_neighbors=10).fit_transform, clouds[:3])
    start = time.perf_counter()
    with (
        get_task_stream(client) as stream,
        joblib.parallel_config(backend="dask"),
        batch_config(batch_points=50_000),
    ):
        on_dask = pfh.fit_transform(clouds)
    print(f"dask:  {on_dask.shape} in {time.perf_counter() - start:.2f} s")
    tasks = [t for t in stream.data if "run_batch" in t["key"]]

print("bit-identical:", np.array_equal(local, on_dask, equal_nan=True))

# %%
# The batches, one bar per worker: when each ran (seconds from the first start).
workers = sorted({t["worker"] for t in tasks})
t0 = min((s["start"] for t in tasks for s in t["startstops"]), default=0.0)
fig, ax = plt.subplots(figsize=(6, 2.0))
for row, worker in enumerate(workers):
    spans = [
        (s["start"] - t0, s["stop"] - s["start"])
        for t in tasks
        if t["worker"] == worker
        for s in t["startstops"]
        if s["action"] == "compute"
    ]
    colours = ["tab:blue", "tab:orange"] * len(spans)
    ax.broken_barh(spans, (row - 0.4, 0.8), facecolors=colours[: len(spans)])
ax.set_yticks(range(len(workers)), [f"worker {i}" for i in range(len(workers))])
ax.set_xlabel("seconds")
ax.set_title(
    f"{len(tasks)} batches of PFH on {len(workers)} Dask workers\n"
    f"{len(clouds)} clouds, {data}",
    fontsize="medium",
)
fig.tight_layout()
plt.show()
