"""The figure of an automatic DBSCAN radius: the distance curve, its fit,
the knee and the radius."""

import numpy as np
from sklearn.utils.validation import check_is_fitted

__all__ = ["plot_eps_curve"]


def plot_eps_curve(estimator, ax=None):
    """Draw a fitted :class:`AutoEpsDBSCAN`'s distance curve, fit, knee and radius.

    Needs matplotlib.

    Parameters
    ----------
    estimator : AutoEpsDBSCAN
        Fitted with ``eps=None``.
    ax : matplotlib Axes, default=None
        Where to draw; a new figure when None.

    Returns
    -------
    ax : matplotlib Axes
        The axes drawn on.

    Examples
    --------
    >>> import matplotlib
    >>> matplotlib.use("Agg")
    >>> import numpy as np
    >>> from skpcd.segmentation import AutoEpsDBSCAN, plot_eps_curve
    >>> rng = np.random.default_rng(0)
    >>> db = AutoEpsDBSCAN().fit(rng.random((500, 3)))
    >>> ax = plot_eps_curve(db)
    >>> ax.get_xlabel()
    'k (nearest neighbours)'
    """
    check_is_fitted(estimator, "eps_")
    if estimator.curve_ is None:
        raise ValueError("the estimator was given eps: there is no curve to plot")
    try:
        import matplotlib.pyplot as plt
    except ImportError as exc:  # pragma: no cover
        raise ImportError("plot_eps_curve needs matplotlib") from exc
    if ax is None:
        _, ax = plt.subplots(figsize=(5, 3.5))
    k = estimator.curve_k_
    grid = np.linspace(k[0], k[-1], 200)
    ax.plot(k, estimator.curve_distances_, "o", ms=3, label="mean k-th NN distance")
    ax.plot(grid, estimator.curve_(grid), "-", label="fitted curve")
    ax.plot(
        [estimator.knee_],
        [estimator.knee_distance_],
        "s",
        color="C3",
        label=f"knee: k={estimator.knee_:.1f}, {estimator.knee_distance_:.3f}",
    )
    ax.axhline(
        estimator.eps_,
        color="C3",
        ls="--",
        lw=1,
        label=f"eps = {estimator.eps_scale:g} x knee = {estimator.eps_:.3f}",
    )
    ax.set_xlabel("k (nearest neighbours)")
    ax.set_ylabel("distance")
    ax.legend(loc="lower right", fontsize="small")
    return ax
