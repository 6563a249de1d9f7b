"""Validation of point-cloud collections: the one place estimators check X."""

import numbers

import numpy as np
from sklearn.utils import check_array
from sklearn.utils.validation import validate_data

__all__ = ["check_point_clouds"]

# How far from 1 the norm of a given normal may be: normals computed in
# float32 (PCL's, skpcd's) are within 1e-6, normals written to text files
# with 4 decimals within 2e-4.
NORMAL_ATOL = 1e-3

NORMALS_OPTIONS = ("auto", "columns", "estimate")


def _as_sequence(X, input_name):
    """Return X as a list of per-cloud objects without stacking it."""
    if isinstance(X, np.ndarray):
        if X.dtype == object:
            if X.ndim != 1:
                raise ValueError(
                    f"{input_name} as an object array must be 1-D (one cloud per "
                    f"element), got shape {X.shape}."
                )
            return list(X)
        if X.ndim == 2:
            raise ValueError(
                f"{input_name} is a single 2-D array of shape {X.shape}; skpcd "
                "expects a sequence of point clouds. Wrap a single cloud in a "
                "list: [cloud]."
            )
        if X.ndim == 3:
            return list(X)
        raise ValueError(
            f"{input_name} must be a sequence of (n_points, 3+) arrays; got an "
            f"array of shape {X.shape}."
        )
    if isinstance(X, (str, bytes)) or not hasattr(X, "__len__"):
        raise TypeError(
            f"{input_name} must be a sequence (list, tuple or 1-D object array) of "
            f"(n_points, 3+) arrays, got {type(X).__name__}."
        )
    return list(X)


def check_point_clouds(
    X,
    *,
    dtype=(np.float64, np.float32),
    min_points=1,
    n_columns=None,
    ensure_all_finite=True,
    copy=False,
    input_name="X",
):
    """Validate a collection of point clouds, one cloud at a time.

    Each cloud is checked with :func:`sklearn.utils.check_array`; the
    collection itself is never turned into one array, so clouds may have
    different numbers of points.

    Parameters
    ----------
    X : sequence of array-like of shape (n_points_i, n_columns_i)
        The clouds: a list, a tuple, a 1-D object array or a 3-D array
        (iterated over its first axis). Columns 0-2 are x, y, z; further
        columns (normals, intensity...) are allowed. A lone 2-D array is
        refused, because it is ambiguous: wrap it as ``[cloud]``.
    dtype : dtype, tuple of dtypes or None, default=(np.float64, np.float32)
        Accepted dtypes, as in :func:`~sklearn.utils.check_array`: a cloud
        whose dtype is in the tuple is kept as it is, others are converted to
        the first one.
    min_points : int, default=1
        Minimum number of points in every cloud. Use 0 to accept empty clouds.
    n_columns : int, tuple of (int, int) or None, default=None
        Required column count: an exact count, an inclusive ``(min, max)``
        range (``max`` may be None), or None for "at least 3".
    ensure_all_finite : bool, default=True
        Refuse NaN and infinite values.
    copy : bool, default=False
        Always copy the clouds (otherwise they are copied only when a
        conversion is needed).
    input_name : str, default="X"
        Name used in error messages.

    Returns
    -------
    clouds : list of ndarray of shape (n_points_i, n_columns_i)
        The validated clouds, in the order given.

    Raises
    ------
    ValueError
        If X is empty, is a single 2-D array, or a cloud has the wrong shape,
        too few points or non-finite values. The message names the cloud by
        its position.
    TypeError
        If X is not a sequence.

    Examples
    --------
    >>> import numpy as np
    >>> from skpcd.utils import check_point_clouds
    >>> clouds = check_point_clouds([np.zeros((5, 3)), np.ones((2, 4))])
    >>> [c.shape for c in clouds]
    [(5, 3), (2, 4)]
    >>> check_point_clouds(np.zeros((5, 3)))
    Traceback (most recent call last):
    ...
    ValueError: X is a single 2-D array of shape (5, 3); skpcd expects a sequence of point clouds. Wrap a single cloud in a list: [cloud].
    """  # noqa: E501
    if not isinstance(min_points, numbers.Integral) or min_points < 0:
        raise ValueError(f"min_points must be a non-negative integer, got {min_points}")
    if n_columns is None:
        lo, hi = 3, None
    elif isinstance(n_columns, numbers.Integral):
        lo = hi = int(n_columns)
    else:
        lo, hi = n_columns
    items = _as_sequence(X, input_name)
    if len(items) == 0:
        raise ValueError(f"{input_name} is empty: at least one point cloud is needed.")
    clouds = []
    for i, cloud in enumerate(items):
        where = f"{input_name}[{i}]"
        if np.ndim(cloud) != 2:
            raise ValueError(
                f"{where} must be a 2-D array of shape (n_points, 3+), got an "
                f"object with {np.ndim(cloud)} dimension(s)."
            )
        if not _plain_float_array(cloud, dtype, ensure_all_finite, copy):
            cloud = _check_cloud(cloud, dtype, ensure_all_finite, copy, where)
        n, d = cloud.shape
        if d < lo or (hi is not None and d > hi):
            want = (
                f"{lo}"
                if lo == hi
                else f"at least {lo}"
                if hi is None
                else (f"{lo} to {hi}")
            )
            raise ValueError(f"{where} has {d} column(s); {want} are required.")
        if n < min_points:
            raise ValueError(
                f"{where} has {n} point(s); at least {min_points} are required."
            )
        clouds.append(cloud)
    return clouds


def _plain_float_array(cloud, dtype, ensure_all_finite, copy):
    """Whether ``cloud`` is already what :func:`_check_cloud` would return
    unchanged: a 2-D float ndarray of an accepted dtype, finite if asked,
    no copy wanted. The check of many small clouds then costs a few
    microseconds each instead of scikit-learn's ~0.2 ms; anything else (and
    a sum that is not finite) goes through ``check_array`` and its messages.
    """
    if copy or type(cloud) is not np.ndarray or cloud.ndim != 2:
        return False
    accepted = dtype if isinstance(dtype, tuple | list) else (dtype,)
    if cloud.dtype.kind != "f" or not any(cloud.dtype == t for t in accepted):
        return False
    # a finite sum means finite values (sklearn's own first test)
    if not ensure_all_finite:
        return True
    with np.errstate(over="ignore", invalid="ignore"):
        return bool(np.isfinite(cloud.sum()))


def _check_cloud(cloud, dtype, ensure_all_finite, copy, where):
    """One cloud through :func:`sklearn.utils.check_array`, errors named."""
    try:
        return check_array(
            cloud,
            dtype=dtype,
            ensure_all_finite=ensure_all_finite,
            ensure_min_samples=0,
            ensure_min_features=0,
            copy=copy,
            input_name=where,
        )
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from exc


def check_extents(lo, hi, limit, *, input_name="X", what=""):
    """Refuse clouds whose extent along an axis exceeds ``limit``.

    Parameters
    ----------
    lo, hi : ndarray of shape (n_clouds, 3)
        The clouds' bounds (:func:`~skpcd.utils._geometry.cloud_bounds`).
    limit : float
        The largest extent allowed
        (:func:`~skpcd.utils._geometry.max_extent` for squared distances).
    input_name : str, default="X"
        Name used in the error message.
    what : str, default=""
        What overflows beyond ``limit``, for the message.

    Raises
    ------
    ValueError
        Naming the first such cloud, its axis, its bounds and the limit.
    """
    with np.errstate(over="ignore", invalid="ignore"):
        extent = hi - lo
    bad = ~(extent <= limit)
    if bad.any():
        i, axis = np.argwhere(bad)[0]
        raise ValueError(
            f"{input_name}[{i}] spans {extent[i, axis]:.3g} along {'xyz'[axis]} "
            f"(from {lo[i, axis]:.6g} to {hi[i, axis]:.6g}): {what} are not "
            f"representable for such an extent (at most {limit:.3g} in the "
            "units of the data)."
        )


def has_normal_columns(cloud, normals):
    """Whether ``normals`` takes the normals of ``cloud`` from its columns 3-5."""
    if normals == "estimate":
        return False
    return normals == "columns" or cloud.shape[1] >= 6


def check_unit_normals(normals, *, input_name="normals", columns="", hint=""):
    """Check that normals are unit vectors; a row with a NaN is undefined.

    Given normals are used as they are, as PCL's ``setInputNormals`` uses
    them: nothing is renormalised, so a vector that is not of unit length
    would silently bend every angle of the descriptors.

    Parameters
    ----------
    normals : array-like of shape (n_points, 3)
        The normals.
    input_name : str, default="normals"
        Name used in the error message.
    columns : str, default=""
        Where the normals are, said after "normals" in the message.
    hint : str, default=""
        Appended to the error message (what else the caller can do).

    Returns
    -------
    undefined : ndarray of bool of shape (n_points,)
        The rows with a NaN: undefined normals (PCL's ``NormalEstimation``
        writes NaN where it cannot fit a plane).

    Raises
    ------
    ValueError
        If a row without NaN is infinite or its norm differs from 1 by more
        than ``NORMAL_ATOL`` (1e-3); the message counts them and names the
        first.
    """
    v = np.asarray(normals, dtype=np.float64)
    undefined = np.isnan(v).any(axis=1)
    with np.errstate(over="ignore", invalid="ignore"):
        norm = np.sqrt(np.einsum("ij,ij->i", v, v))
    bad = np.flatnonzero(~undefined & ~(np.abs(norm - 1.0) <= NORMAL_ATOL))
    if len(bad):
        first = bad[0]
        raise ValueError(
            f"{input_name}: {len(bad)} of {len(v)} normals{columns} are not unit "
            f"vectors (|norm - 1| > {NORMAL_ATOL:g}); the first is row {first}, norm "
            f"{norm[first]:.6g}. Given normals are used as they are (as PCL "
            "does): normalise them (n / np.linalg.norm(n, axis=1, keepdims=True)) "
            f"and write NaN where a normal is undefined{hint}."
        )
    return undefined


def check_given_normals(clouds, normals, *, estimation=(), input_name="X"):
    """Which clouds carry their normals in columns 3-5, those normals checked.

    Parameters
    ----------
    clouds : list of ndarray of shape (n_points_i, 3+)
        Validated clouds.
    normals : {"auto", "columns", "estimate"}
        ``"auto"``: the clouds with 6 or more columns carry normals;
        ``"columns"``: every cloud does (fewer than 6 columns is an error);
        ``"estimate"``: none (the columns are not read).
    estimation : sequence of str, default=()
        Names of the parameters, set away from their default, that only
        control how normals are estimated: an error for a cloud whose
        normals are given, as they would be ignored.
    input_name : str, default="X"
        Name used in error messages.

    Returns
    -------
    given : list of bool
        One per cloud: True where its normals are columns 3-5.
    """
    given = []
    for i, c in enumerate(clouds):
        where = f"{input_name}[{i}]"
        if normals == "columns" and c.shape[1] < 6:
            raise ValueError(
                f"{where} has {c.shape[1]} columns; normals='columns' reads the "
                "normals from columns 3-5."
            )
        has = has_normal_columns(c, normals)
        if has and estimation:
            names = " and ".join(estimation)
            raise ValueError(
                f"{where} has normals in columns 3-5, which normals={normals!r} "
                f"uses as they are; {names} only set how normals are estimated "
                "and would be ignored. Pass normals='estimate' to estimate the "
                f"normals instead, or leave {names} at the default."
            )
        if has:
            check_unit_normals(
                c[:, 3:6],
                input_name=where,
                columns=" (columns 3-5)",
                hint=", or pass normals='estimate' to estimate them instead",
            )
        given.append(has)
    return given


def refuse_sequence(X):
    """A list of clouds given where one cloud is expected: a clear error."""
    if (
        isinstance(X, (list, tuple))
        or (isinstance(X, np.ndarray) and X.dtype == object)
    ) and any(np.ndim(c) == 2 for c in X):
        raise ValueError(
            "X must be one point cloud, an array of shape (n_points, 3+); got a "
            "sequence of clouds: segment each cloud on its own."
        )


def check_scene(X, estimator=None, *, min_points=1, reset=True):
    """One cloud as X: ``(n_points, 3+)`` to contiguous float64 xyz.

    Columns beyond the third (intensity...) are ignored; fewer than three
    is an error (a scene has x, y and z). With an estimator, sklearn's
    :func:`~sklearn.utils.validation.validate_data` checks X and records
    ``n_features_in_``.
    """
    kwargs = {"dtype": np.float64, "ensure_min_samples": min_points}
    refuse_sequence(X)
    if estimator is None:
        X = check_array(X, input_name="X", **kwargs)
    else:
        X = validate_data(estimator, X, reset=reset, **kwargs)
    if X.shape[1] < 3:
        name = "the scene" if estimator is None else type(estimator).__name__
        raise ValueError(
            f"X has {X.shape[1]} feature(s); {name} needs at least 3 columns "
            "(x, y, z); columns beyond the third are ignored."
        )
    if X.shape[1] == 3:
        return np.ascontiguousarray(X)  # no copy when it already is
    return np.ascontiguousarray(X[:, :3])
