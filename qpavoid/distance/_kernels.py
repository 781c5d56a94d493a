"""The sphere distance table's arithmetic, compiled (numba): one pass over the pairs.

:class:`~qpavoid.distance.methods.SphereDistance` says *what* is compared (which robot point
with which human point for each robot set and human part); :func:`sphere_table` computes
eq. (1) for all of them in one call, instead of a dozen numpy calls on (P, M, 3) arrays
whose call overhead outweighed their arithmetic (docs/performance.md measures it). The
compiled code is cached on disk (``cache=True``); :func:`warm_up` compiles or loads it.
"""

from __future__ import annotations

import functools

import numpy as np
from numba import njit

from qpavoid.core import geometry
from qpavoid.core.compiling import ctrl_c_deferred, recompile_if_stale
from qpavoid.core.geometry import TINY

__all__ = [
    "capsule_axes",
    "capsule_directions",
    "capsule_table",
    "segment_closest",
    "sphere_table",
    "warm_up",
]


@njit(cache=True)
def sphere_table(
    robot_points: np.ndarray,
    human_points: np.ndarray,
    human_valid: np.ndarray,
    pairs: np.ndarray,
    radii: np.ndarray,
    part_margin: np.ndarray,
    fallback: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Eq. (1) for every (robot set, human part) row of ``pairs``.

    Row ``r`` lists flat pair indices ``p M + m`` (robot point ``p``, human point ``m``,
    ``M`` human points), padded with ``P M`` (no pair). Its distance is

    .. math:: d_r = \\min_{(p, m)} \\lVert x_p - h_m \\rVert - \\rho_r - \\mu_r

    over the pairs whose human point is usable (``human_valid``), with the summed sphere
    radii :math:`\\rho_r` (``radii``) and the part's margin :math:`\\mu_r`
    (``part_margin[r % n_parts]``); the first minimum wins.

    Returns
    -------
    distance
        (R,) m; ``inf`` where no pair is usable.
    direction
        (R, 3) unit vector from the human point to the robot point (0 where the distance
        is infinite, ``fallback`` where the points coincide).
    robot_point, human_point
        (R,) indices of the closest pair (-1 where the distance is infinite).
    """
    n_rows, width = pairs.shape
    M = human_points.shape[0]
    pad = robot_points.shape[0] * M
    n_parts = part_margin.shape[0]
    distance = np.empty(n_rows)
    direction = np.zeros((n_rows, 3))
    robot_point = np.full(n_rows, -1, dtype=np.int64)
    human_point = np.full(n_rows, -1, dtype=np.int64)
    for r in range(n_rows):
        best, best_value = pad, np.inf
        for k in range(width):
            flat = pairs[r, k]
            if flat == pad or not human_valid[flat % M]:
                continue
            p, m = flat // M, flat % M
            dx = robot_points[p, 0] - human_points[m, 0]
            dy = robot_points[p, 1] - human_points[m, 1]
            dz = robot_points[p, 2] - human_points[m, 2]
            value = np.sqrt(dx * dx + dy * dy + dz * dz)
            if value < best_value:
                best, best_value = flat, value
        distance[r] = best_value - radii[r] - part_margin[r % n_parts]
        if best == pad:
            continue
        p, m = best // M, best % M
        robot_point[r], human_point[r] = p, m
        if best_value < TINY:  # no direction between the points: the fallback
            direction[r] = fallback
        else:
            for k in range(3):
                direction[r, k] = (robot_points[p, k] - human_points[m, k]) / best_value
    return distance, direction, robot_point, human_point


@njit(cache=True)
def capsule_axes(segments: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Axis ``b − a`` (N, 3), half length (N,) and centre (N, 3) of the segments
    ``(a, b)`` (N, 2, 3), m (NaN in, NaN out)."""
    n = segments.shape[0]
    axis, half, centre = np.empty((n, 3)), np.empty(n), np.empty((n, 3))
    for i in range(n):
        length2 = 0.0
        for k in range(3):
            axis[i, k] = segments[i, 1, k] - segments[i, 0, k]
            centre[i, k] = 0.5 * (segments[i, 0, k] + segments[i, 1, k])
            length2 += axis[i, k] * axis[i, k]
        half[i] = 0.5 * np.sqrt(length2)
    return axis, half, centre


@njit(cache=True)
def capsule_directions(
    segments: np.ndarray,
    distance: np.ndarray,
    robot_point: np.ndarray,
    human_point: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The capsule table's directions and axis parameters from coal's witness points.

    Row ``r`` is the pair of robot set ``r // K`` (``K = R / S``) with a body part. Its
    direction is ``(robot_point − human_point) / d`` (the unit vector from the human to
    the robot; unscaled where ``d ≤ 1e-9``, for the caller to replace, and 0 for a part
    not seen, ``d = inf``); its parameter is that of the robot witness point's projection
    on the set's axis ``a → b``, clipped to [0, 1] (0 for a part not seen).

    Returns
    -------
    vector
        (R, 3).
    s
        (R,).
    """
    n_rows, n_sets = distance.shape[0], segments.shape[0]
    n_parts = n_rows // n_sets
    vector = np.zeros((n_rows, 3))
    s = np.zeros(n_rows)
    for r in range(n_rows):
        d = distance[r]
        if not np.isfinite(d):
            continue
        i = r // n_parts
        scale = d if d > 1e-9 else 1.0
        along, length2 = 0.0, 0.0
        for k in range(3):
            vector[r, k] = (robot_point[r, k] - human_point[r, k]) / scale
            ab = segments[i, 1, k] - segments[i, 0, k]
            along += (robot_point[r, k] - segments[i, 0, k]) * ab
            length2 += ab * ab
        s[r] = min(max(along / max(length2, 1e-18), 0.0), 1.0)
    return vector, s


@njit(cache=True, inline="always")
def _clamp01(x: float) -> float:
    return min(max(x, 0.0), 1.0)


@njit(cache=True)
def segment_closest(
    p1: np.ndarray, q1: np.ndarray, p2: np.ndarray, q2: np.ndarray
) -> tuple[float, float]:
    r"""The parameters ``(s, t)`` of the closest points ``p1 + s (q1 − p1)`` and
    ``p2 + t (q2 − p2)`` of two segments, each in [0, 1].

    The squared distance is a convex quadratic in (s, t) on the unit square, so its
    minimum is the lines' closest pair where that lies inside, else on an edge: one end of
    a segment against the other segment (Ericson, *Real-Time Collision Detection* (2005),
    §5.1.9). With ``d₁ = q1 − p1``, ``d₂ = q2 − p2``, ``r = p1 − p2``, ``a = d₁·d₁``,
    ``e = d₂·d₂``, ``b = d₁·d₂``, ``c = d₁·r``, ``f = d₂·r`` and ``n = d₁ × d₂``:

    .. math:: s = rac{n · (d_2 × r)}{‖n‖^2}, \qquad t = rac{b s + f}{e}

    (``‖n‖² = a e − b²`` and ``n · (d₂ × r) = b f − c e``, written as cross products:
    no cancellation when the segments are nearly parallel), clamped as Ericson clamps
    them; the four edges' pairs are each end's projection on the other segment, clamped.
    The closest of these five pairs, measured from the points, is returned: exact to
    rounding however nearly parallel the segments (crossing ones included), and for
    parallel ones (``n = 0``) a pair of the overlap. A segment of zero length (``a`` or
    ``e`` below :data:`~qpavoid.core.geometry.TINY`² m²) is its point.
    """
    # scalars throughout: a pair is a few dozen flops, an array allocation would outweigh it
    u0, u1, u2 = q1[0] - p1[0], q1[1] - p1[1], q1[2] - p1[2]  # d₁
    v0, v1, v2 = q2[0] - p2[0], q2[1] - p2[1], q2[2] - p2[2]  # d₂
    r0, r1, r2 = p1[0] - p2[0], p1[1] - p2[1], p1[2] - p2[2]  # r
    a = u0 * u0 + u1 * u1 + u2 * u2
    e = v0 * v0 + v1 * v1 + v2 * v2
    b = u0 * v0 + u1 * v1 + u2 * v2
    c = u0 * r0 + u1 * r1 + u2 * r2
    f = v0 * r0 + v1 * r1 + v2 * r2
    small = TINY * TINY
    if a <= small and e <= small:  # two points
        return 0.0, 0.0
    if a <= small:  # the first a point: its projection on the second
        return 0.0, _clamp01(f / e)
    if e <= small:  # the second a point
        return _clamp01(-c / a), 0.0
    n0, n1, n2 = u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0  # n = d₁ × d₂
    denom = n0 * n0 + n1 * n1 + n2 * n2
    best_s, best_t, best = 0.0, 0.0, np.inf
    for k in range(5):
        if k == 0:  # p1 against the second segment
            s, t = 0.0, _clamp01(f / e)
        elif k == 1:  # q1 against the second segment
            s, t = 1.0, _clamp01((b + f) / e)
        elif k == 2:  # p2 against the first
            s, t = _clamp01(-c / a), 0.0
        elif k == 3:  # q2 against the first
            s, t = _clamp01((b - c) / a), 1.0
        elif denom > 0.0:  # the lines' closest pair, clamped: n · (d₂ × r) / ‖n‖²
            w0, w1, w2 = v1 * r2 - v2 * r1, v2 * r0 - v0 * r2, v0 * r1 - v1 * r0
            s = _clamp01((n0 * w0 + n1 * w1 + n2 * w2) / denom)
            t = _clamp01((b * s + f) / e)
            s = _clamp01((b * t - c) / a)
        else:  # parallel: the ends' pairs cover the overlap
            break
        # the squared gap from the points themselves (no cancellation of expanded terms)
        x0 = r0 + s * u0 - t * v0
        x1 = r1 + s * u1 - t * v1
        x2 = r2 + s * u2 - t * v2
        gap = x0 * x0 + x1 * x1 + x2 * x2
        if gap < best:
            best, best_s, best_t = gap, s, t
    return best_s, best_t


@njit(cache=True)
def capsule_table(
    robot_segments: np.ndarray,
    robot_radii: np.ndarray,
    human_segments: np.ndarray,
    human_radii: np.ndarray,
    human_valid: np.ndarray,
    n_parts: int,
    fallback: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    r"""Signed capsule–capsule distances of every robot set with every body part, the
    closest of the people: one pass.

    Robot set ``i`` is the capsule of axis ``robot_segments[i]`` (a → b) and radius
    ``robot_radii[i]``; part ``j`` of person ``p`` the capsule at row ``p P + j`` of
    ``human_segments``, ``human_radii`` (margins included) and ``human_valid``
    (``P = n_parts``). With the axes' closest points ``c_r``, ``c_h``
    (:func:`segment_closest`), the signed distance is

    .. math:: d = \lVert c_r − c_h \rVert − ρ_r − ρ_h,

    exact apart and in penetration (the distance between the axes is 1-Lipschitz in a
    translation, so no shorter one separates them), its direction
    ``n = (c_r − c_h) / ‖c_r − c_h‖`` (human → robot), the witness points on the surfaces
    ``c_r − ρ_r n`` and ``c_h + ρ_h n``, and ``s`` the robot's axis parameter of ``c_r``
    (the point whose Jacobian the table's rows use). Where the axes meet (``‖c_r − c_h‖
    < TINY``) ``n`` is the unit normal of both axes (``d₁ × d₂``), else one of the robot
    axis alone, else ``fallback``. Row ``r = i P + j`` keeps the closest person, the first
    of equals.

    Returns
    -------
    distance
        (S P,) m; +inf where no person's part is valid; −inf where a valid part (or the
        arm's capsule) holds a NaN: in doubt, in contact (the input checks keep NaN out
        of valid parts; this keeps a NaN from reading as nobody there).
    vector
        (S P, 3) unit, 0 where the distance is infinite.
    s
        (S P,) in [0, 1] (0 where the distance is infinite).
    robot_point, human_point
        (S P, 3) m (NaN where the distance is infinite).
    who
        (S P,) the person of each row (0 where the distance is infinite).
    """
    n_sets = robot_segments.shape[0]
    n_people = human_segments.shape[0] // n_parts
    n_rows = n_sets * n_parts
    distance = np.full(n_rows, np.inf)
    vector = np.zeros((n_rows, 3))
    s_out = np.zeros(n_rows)
    robot_point = np.full((n_rows, 3), np.nan)
    human_point = np.full((n_rows, 3), np.nan)
    who = np.zeros(n_rows, dtype=np.int64)
    c_r, c_h, n = np.empty(3), np.empty(3), np.empty(3)
    for i in range(n_sets):
        a_r, b_r = robot_segments[i, 0], robot_segments[i, 1]
        for j in range(n_parts):
            row = i * n_parts + j
            for p in range(n_people):
                h = p * n_parts + j
                if not human_valid[h]:
                    continue
                a_h, b_h = human_segments[h, 0], human_segments[h, 1]
                s, t = segment_closest(a_r, b_r, a_h, b_h)
                gap2 = 0.0
                for k in range(3):
                    c_r[k] = a_r[k] + s * (b_r[k] - a_r[k])
                    c_h[k] = a_h[k] + t * (b_h[k] - a_h[k])
                    gap2 += (c_r[k] - c_h[k]) ** 2
                gap = np.sqrt(gap2)
                d = gap - robot_radii[i] - human_radii[h]
                if d != d:  # NaN in a valid part or the arm: in doubt, in contact
                    distance[row], s_out[row], who[row] = -np.inf, 0.0, p
                    for k in range(3):
                        vector[row, k] = fallback[k]
                        robot_point[row, k] = human_point[row, k] = np.nan
                    break  # nothing is closer than −inf
                if not d < distance[row]:  # the first of equals is kept
                    continue
                if gap >= TINY:
                    for k in range(3):
                        n[k] = (c_r[k] - c_h[k]) / gap
                else:
                    _normal_of_axes(a_r, b_r, a_h, b_h, fallback, n)
                distance[row], s_out[row], who[row] = d, s, p
                for k in range(3):
                    vector[row, k] = n[k]
                    robot_point[row, k] = c_r[k] - robot_radii[i] * n[k]
                    human_point[row, k] = c_h[k] + human_radii[h] * n[k]
    return distance, vector, s_out, robot_point, human_point, who


@njit(cache=True)
def _normal_of_axes(
    a_r: np.ndarray,
    b_r: np.ndarray,
    a_h: np.ndarray,
    b_h: np.ndarray,
    fallback: np.ndarray,
    n: np.ndarray,
) -> None:
    """Into ``n``: a unit vector normal to both axes where they meet (their cross
    product), else normal to the robot's axis (its cross product with the coordinate axis
    it leans on least), else ``fallback`` (a point on a point)."""
    u, v = b_r - a_r, b_h - a_h
    w = np.cross(u, v)
    norm = np.sqrt(w @ w)
    if norm < TINY:
        e = np.zeros(3)
        e[np.argmin(np.abs(u))] = 1.0
        w = np.cross(u, e)
        norm = np.sqrt(w @ w)
    if norm < TINY:
        w, norm = fallback, 1.0
    for k in range(3):
        n[k] = w[k] / norm


@functools.cache
def warm_up() -> None:
    """Compile (or load from the disk cache) the kernels, once per process; the sphere
    table again if :mod:`qpavoid.core.geometry` changed after its cache was written (it
    compiles :data:`~qpavoid.core.geometry.TINY` in:
    :func:`~qpavoid.core.compiling.recompile_if_stale`)."""
    with ctrl_c_deferred():  # a Ctrl-C while the kernel compiles comes right after
        sphere_table(
            np.zeros((2, 3)),
            np.ones((3, 3)),
            np.ones(3, dtype=np.bool_),
            np.zeros((2, 2), dtype=np.int64),
            np.zeros(2),
            np.zeros(2),
            np.zeros(3),
        )
        capsule_directions(np.zeros((1, 2, 3)), np.ones(2), np.zeros((2, 3)), np.ones((2, 3)))
        capsule_axes(np.zeros((1, 2, 3)))
        capsule_table(
            np.zeros((1, 2, 3)),
            np.ones(1),
            np.ones((2, 2, 3)),
            np.ones(2),
            np.ones(2, dtype=np.bool_),
            1,
            np.zeros(3),
        )
        for kernel in (sphere_table, capsule_table):  # they compile geometry.TINY in
            recompile_if_stale(kernel, geometry)
