"""
One command for every kind of scan: airborne, profiler, spinning sensor, robot
==============================================================================

``segment_scene(points)`` (and ``skpcd segment scan.las -o out/``) first asks
:func:`skpcd.segmentation.describe_scan` what the scan is, from the points alone:

- seen from above (few vertical surfaces): **airborne**, ground by SMRF;
- points concentrated around one position, at most 500,000 of them: one sweep of a
  **spinning** sensor (a **robot** when a sensor position less than 1.2 m above the
  ground is given), ground by the cloth simulation filter with the bases of objects
  given back, clusters with a radius proportional to the distance to the sensor
  (estimated from the sweep: it bridges the sensor's rings);
- otherwise a car-mounted **profiler** scan, the same ground filter.

The same street is simulated here with the four patterns
(:func:`skpcd.datasets.make_street_scene`, 40 m), and segmented with no option at
all. Each panel is a top view; the ground is grey, each segment a colour. The
measurements on real scans of each kind are in the user guide (:ref:`segmentation`).
"""

import matplotlib.pyplot as plt
import numpy as np

from skpcd.datasets import make_street_scene
from skpcd.segmentation import segment_scene

PATTERNS = {
    "aerial": ("aerial", None, None),
    "profiler": ("mobile", {"angular_step": 0.4, "rotation_rate": 50.0}, None),
    "spinning (HDL-64E)": ("spinning", {"sensor": "hdl64"}, None),
    "robot (VLP-16 at 0.6 m)": ("ugv", {"height": 0.6, "azimuth_step": 0.4}, 0.6),
}

results = {}
for title, (scanner, params, up) in PATTERNS.items():
    s = make_street_scene(40.0, scanner=scanner, scanner_params=params, random_state=4)
    sensor = None
    if up is not None:  # a robot's sensor position is known to its software
        x, y = s.trajectory[0, :2]
        sensor = (x, y, float(s.ground_height(x, y)) + up)
    seg = segment_scene(s.points, sensor=sensor)
    truth = s.labels == "ground"
    recall = seg.ground[truth].mean()
    precision = truth[seg.ground].mean()
    results[title] = (s.points, seg)
    print(
        f"{title:<24} {len(s.points):>8} points: {seg.scan.kind:<9} "
        f"ground {seg.ground_filter!r}, eps {seg.eps:.2f} m, "
        f"{seg.n_segments} segments, "
        f"ground recall {recall:.3f}, precision {precision:.3f}"
    )

# %%
# The segments, top view
# ----------------------

fig, axes = plt.subplots(2, 2, figsize=(10, 7), sharex=True, sharey=True)
rng = np.random.default_rng(0)
for ax, (title, (points, seg)) in zip(axes.ravel(), results.items()):
    palette = rng.random((max(seg.n_segments, 1), 3)) * 0.8
    show = rng.random(len(points)) < min(1.0, 60000 / len(points))
    colors = np.full((len(points), 3), 0.95)  # no segment: near white
    colors[seg.ground] = 0.75  # ground: grey
    inside = seg.labels >= 0
    colors[inside] = palette[seg.labels[inside]]
    ax.scatter(*points[show, :2].T, c=colors[show], s=0.3, linewidths=0)
    ax.set_title(f"{title}: {seg.scan.kind}, {seg.n_segments} segments", fontsize=9)
    ax.set_aspect("equal")
    ax.set_xlim(0, 40)
    ax.set_ylim(-20, 20)
fig.supxlabel("x (m)")
fig.supylabel("y (m)")
fig.tight_layout()
plt.show()
