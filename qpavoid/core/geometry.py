"""Vector helpers shared by the modules (the lowest module: it imports only numpy)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

#: Norm below which :func:`unit` returns its ``fallback`` direction.
TINY = 1e-12


def unit(
    v: ArrayLike,
    fallback: ArrayLike | None = None,
    *,
    norm: ArrayLike | None = None,
    floor: float = 0.0,
) -> np.ndarray:
    """Unit vector(s) ``v / ‖v‖`` along the last axis.

    Parameters
    ----------
    v
        A vector (n,) or a stack of them (..., n).
    fallback
        Direction (n,) returned where ``‖v‖ < TINY``; ``None`` (default): no check.
    norm
        ``‖v‖`` (shape ``v.shape[:-1]``) if the caller has it already.
    floor
        Divide by ``max(‖v‖, floor)``: a vector shorter than ``floor`` is scaled by
        ``1 / floor`` instead of blowing up (used without ``fallback``).

    Returns
    -------
    numpy.ndarray
        Same shape as ``v``, float.
    """
    v = np.asarray(v, dtype=float)
    if norm is None:
        norm = np.linalg.norm(v) if v.ndim == 1 else np.linalg.norm(v, axis=-1)
    norm = np.asarray(norm, dtype=float)
    if fallback is None:
        return v / np.maximum(norm, floor)[..., None]
    small = norm < TINY
    out = v / np.where(small, 1.0, norm)[..., None]
    out[small] = fallback
    return out


def point_segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distances from points ``p`` (..., 3) to the segments ``[a, b]`` (..., 3), m.

    The closest point is ``a + s (b − a)`` with ``s = clip((p − a)·(b − a) / ‖b − a‖², 0, 1)``
    (a degenerate segment is its end point).
    """
    ab, ap = b - a, p - a
    s = (ap * ab).sum(axis=-1) / np.maximum((ab * ab).sum(axis=-1), TINY)
    d = ap - np.minimum(np.maximum(s, 0.0), 1.0)[..., None] * ab
    return np.sqrt((d * d).sum(axis=-1))
