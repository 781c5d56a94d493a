"""Joint velocity limits: nominal, with A1 and A2 scaled by (1 − f) (eq. 3)."""

from __future__ import annotations

import numpy as np

from .layout import QPInput


class VelocityLimit:
    """Bounds ``−q̇_max,r ≤ q̇ ≤ q̇_max,r`` with ``q̇_max,r`` of eq. (3) (rad/s).

    The shared prelude already scaled the limits of the L1 joints (A1, A2) by (1 − f).
    """

    def compute_qp_bounds(self, inp: QPInput) -> tuple[np.ndarray, np.ndarray]:
        lim = inp.tick.limits
        return -lim, lim
