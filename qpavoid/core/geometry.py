"""Vector and rotation helpers shared by the modules (numpy, and core's argument checks)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from qpavoid.core.checks import as_array

#: The library's one "tiny": a norm below which :func:`unit` returns its ``fallback``
#: direction, a segment shorter than which is its end point
#: (:func:`~qpavoid.human._kernels.point_segment_distance`), a distance below which two
#: points have no direction between them (:mod:`qpavoid.distance._kernels`), m. A compiled
#: kernel freezes it in: its disk cache sees an edit here only through
#: :func:`~qpavoid.core.compiling.recompile_if_stale`.
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


def orthonormalize(R: ArrayLike) -> np.ndarray:
    """Nearest rotation matrix (the paper prints its matrices to 3-4 digits): ``U diag(1,
    1, det(U Vᵀ)) Vᵀ`` of the SVD ``R = U Σ Vᵀ``.

    Raises
    ------
    InputError
        If ``R`` is not a finite (3, 3) array (the SVD would fail on a non-finite one).
    """
    U, _, Vt = np.linalg.svd(as_array(R, (3, 3), "R (rotation matrix)"))
    return U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
