"""The end-effector task of eq. (8) as a least-squares cost."""

from __future__ import annotations

import numpy as np

from .layout import Layout, QPInput


class EndEffectorTask:
    """Cost ``‖W (J q̇ − v*)‖²`` with ``v* = v_PL + K e + [v_EE; 0]`` (eq. 8).

    ``J`` is the (6, nv) end-effector Jacobian (twist ``[v; ω]`` in the base frame),
    ``W = diag(w_p, w_p, w_p, w_o, w_o, w_o)``. Expanded, up to a constant:
    ``q̇ᵀ (JᵀW²J) q̇ − 2 (JᵀW²v*)ᵀ q̇``, so with the ``½ xᵀHx + cᵀx`` convention
    ``H = 2 JᵀW²J`` and ``c = −2 JᵀW²v*``.

    Parameters
    ----------
    layout
        The QP's variables.
    K
        (6,) diagonal gain of eq. (8), 1/s.
    weight_position, weight_orientation
        w_p (per m/s) and w_o (per rad/s).
    """

    def __init__(self, layout: Layout, K: np.ndarray, weight_position: float, weight_orientation: float):
        self.layout, self.K = layout, np.asarray(K, dtype=float)
        self.w2 = np.r_[[weight_position ** 2] * 3, [weight_orientation ** 2] * 3]

    def target(self, inp: QPInput) -> np.ndarray:
        """v* of eq. (8): planned twist + K e + the EE repulsion (linear part), (6,)."""
        t = inp.tick
        v = t.ref_twist + self.K * t.error
        v[:3] += inp.v_rep_EE
        return v

    def compute_qp_objective(self, inp: QPInput) -> tuple[np.ndarray, np.ndarray]:
        """(H, c) over the joint velocities (nv, nv), (nv,)."""
        J = inp.tick.kin.ee_jacobian
        JW = J.T * self.w2
        return 2.0 * JW @ J, -2.0 * JW @ self.target(inp)
