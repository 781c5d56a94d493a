"""Input validation shared by the modules (internal)."""

from __future__ import annotations

import numpy as np

from .errors import InputError


def as_array(value, shape: tuple[int | None, ...], name: str, *, finite: bool = True) -> np.ndarray:
    """Return ``value`` as a float array of ``shape`` (``None`` = any size) or raise InputError.

    Parameters
    ----------
    value
        Anything numpy can turn into a float array.
    shape
        Expected shape; ``None`` entries accept any length.
    name
        Name of the argument, used in the error message.
    finite
        If True, NaN or infinite entries are rejected too.
    """
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be numeric, got {type(value).__name__}") from exc
    if arr.shape != shape and (arr.ndim != len(shape) or any(
            s is not None and s != n for s, n in zip(shape, arr.shape))):
        want = str(tuple("N" if s is None else s for s in shape)).replace("'", "")
        raise InputError(f"{name} must have shape {want}, got {arr.shape}")
    if finite and not np.isfinite(arr).all():
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise InputError(f"{name} has a non-finite entry at index {tuple(int(i) for i in bad)}: "
                         f"{arr[tuple(bad)]}")
    return arr
