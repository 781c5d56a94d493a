"""Joint position limits turned into velocity bounds for the next control period."""

from __future__ import annotations

import numpy as np

from .layout import QPInput


class PositionLimit:
    """Bounds ``γ (q_min − q) / dt ≤ q̇ ≤ γ (q_max − q) / dt``.

    After one period of length dt, ``q_max − q`` shrinks at most by the factor (1 − γ), so
    a joint inside its limits never crosses them (it approaches geometrically).

    Parameters
    ----------
    q_min, q_max
        Position limits, rad.
    gain
        γ in (0, 1].
    """

    def __init__(self, q_min: np.ndarray, q_max: np.ndarray, gain: float):
        self.q_min, self.q_max, self.gain = q_min, q_max, gain

    def compute_qp_bounds(self, inp: QPInput) -> tuple[np.ndarray, np.ndarray]:
        k = self.gain / inp.dt
        q = inp.tick.q
        return k * (self.q_min - q), k * (self.q_max - q)
