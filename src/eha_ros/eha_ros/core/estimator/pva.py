"""Position-velocity-acceleration Kalman filter, eqs. 4.30-4.34 (appendix C.4): the motion is
modelled as white jerk of intensity W; only the position is measured."""
from __future__ import annotations

import numpy as np

from . import kernels


def pva_matrices(Ts: float, W: float):
    """F of eq. 4.30 and Q of eq. 4.32 (continuous white jerk W sampled at Ts)."""
    F = np.array([[1.0, Ts, 0.5 * Ts * Ts], [0.0, 1.0, Ts], [0.0, 0.0, 1.0]])
    Q = W * np.array([
        [Ts ** 5 / 20, Ts ** 4 / 8, Ts ** 3 / 6],
        [Ts ** 4 / 8, Ts ** 3 / 3, Ts ** 2 / 2],
        [Ts ** 3 / 6, Ts ** 2 / 2, Ts]])
    return F, Q


class PvaKF(kernels.StateView):
    """PVA filter: H = [1 0 0] (eq. 4.31), R (eq. 4.33), P0 (eq. 4.34), Joseph update."""

    def __init__(self, Ts: float, W: float, R: float, p0_diag=(1e-6, 1e-2, 1e2)):
        self.Ts = Ts
        self.F, self.Q = pva_matrices(Ts, W)
        self.G = np.zeros((3, 1))
        self.H = np.array([[1.0, 0.0, 0.0]])
        self.R = np.array([[R]])
        self.P0 = np.diag(np.asarray(p0_diag, float))
        self._u = np.zeros(1)
        self._tmp = kernels.scratch(3)
        self.y, self.S = np.zeros(1), np.zeros((1, 1))
        self.reset()

    def reset(self, position: float = 0.0, p_a: float | None = None, p_b: float | None = None):
        """Initial state at ``position`` at rest (pressures unused: the PVA model has none)."""
        kernels.refill(self, 'x', (position, 0.0, 0.0))
        kernels.refill(self, 'P', self.P0)

    def predict(self, omega: float = 0.0, p_D: float | None = None):
        """One Ts of eq. 4.30 (inputs ignored: the PVA model has none)."""
        kernels.predict(self.x, self.P, self.F, self.G, self._u, self.Q, self._tmp)

    def update(self, z_pos: float, p_a: float | None = None, p_b: float | None = None):
        """Position update (pressures unused); returns (innovation, S, NIS, measurement dimension 1)."""
        nis = kernels.update(self.x, self.P, self.H, self.R, np.array((z_pos,)), self.y, self.S)
        return float(self.y[0]), float(self.S[0, 0]), float(nis), 1

    def innovation_only(self, z_pos: float):
        return z_pos - float(self.x[0]), float(self.P[0, 0] + self.R[0, 0])

    @property
    def acceleration(self) -> float:
        return float(self.x[2])
