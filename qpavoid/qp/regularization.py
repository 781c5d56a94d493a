"""A small regularisation of the joint velocities."""

from __future__ import annotations

import numpy as np

from .layout import Layout, QPInput


class Regularization:
    """Cost ``ε ‖q̇‖²``: keeps H positive definite whatever the Jacobian's rank."""

    constant = True

    def __init__(self, layout: Layout, epsilon: float):
        self.layout, self.epsilon = layout, epsilon
        n, nv = layout.n, layout.nv
        self._H = np.zeros((n, n))
        self._H[np.arange(nv), np.arange(nv)] = 2.0 * epsilon
        self._c = np.zeros(n)
        self._H.setflags(write=False)
        self._c.setflags(write=False)

    def compute_qp_objective(self, inp: QPInput) -> tuple[np.ndarray, np.ndarray]:
        """(H, c): ``2ε I`` on the joint velocities, 0 elsewhere (constant)."""
        return self._H, self._c
