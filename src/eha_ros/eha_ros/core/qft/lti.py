"""Low-order controller transfer functions in zeros/poles/gain form: eqs. 4.65, 4.74, 4.77.

Responses are evaluated from the factored form; state-space realisations are cascades of
first-order sections (no polynomial root-finding); num/den polynomials are only formed for the
YAML output (order <= 4, well conditioned)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Zpk:
    """k * prod(s - z) / prod(s - p), real zeros and poles, proper (len(z) <= len(p))."""

    zeros: tuple
    poles: tuple
    gain: float

    def __post_init__(self):
        if len(self.zeros) > len(self.poles):
            raise ValueError('improper transfer function')

    def freq(self, w) -> np.ndarray:
        """G(j w) for angular frequencies w (rad/s), any shape."""
        s = 1j * np.asarray(w, float)
        h = np.full(s.shape, self.gain, complex)
        for z in self.zeros:
            h = h * (s - z)
        for p in self.poles:
            h = h / (s - p)
        return h

    def ss(self):
        """(A, B, C, D) as a cascade of sections (s - z)/(s - p) = 1 + (p - z)/(s - p), then 1/(s - p)."""
        secs = []
        nz = len(self.zeros)
        for i, p in enumerate(self.poles):
            if i < nz:
                secs.append((p, 1.0, p - self.zeros[i], 1.0))
            else:
                secs.append((p, 1.0, 1.0, 0.0))
        n = len(secs)
        A = np.zeros((n, n))
        B = np.zeros((n, 1))
        C = np.zeros((1, n))
        D = np.ones((1, 1))
        # signal flows section 0 -> 1 -> ... ; u_k = C_{k-1} x_{k-1} + D_{k-1} u_{k-1}
        cin = np.zeros(n)   # row giving the input of the current section from states
        din = 1.0           # direct part from the external input
        for k, (p, b, c, d) in enumerate(secs):
            A[k, k] = p
            A[k, :k] += b * cin[:k]
            B[k, 0] = b * din
            cin = d * cin
            cin[k] += c
            din = d * din
        C[0, :] = self.gain * cin
        D[0, 0] = self.gain * din
        return A, B, C, D

    def num_den(self):
        """Polynomial coefficients in descending powers of s (for the controller YAML)."""
        num = self.gain * np.poly(np.asarray(self.zeros, float)) if self.zeros else \
            np.array([self.gain])
        den = np.poly(np.asarray(self.poles, float))
        return [float(v) for v in np.atleast_1d(num)], [float(v) for v in np.atleast_1d(den)]


def velocity_controller(K1: float, K2: float, K3: float, k_T: float) -> Zpk:
    """Eq. 4.65: G_v(s) = (1/k_T)(K1 + K2/s) / (s/K3 + 1)  [A per rad/s]."""
    return Zpk((-K2 / K1,), (0.0, -K3), K1 * K3 / k_T)


def position_controller(K: float, z, p) -> Zpk:
    """Eq. 4.74: G(s) = K/s prod (1 + s/z_i)/(1 + s/p_i)  [rad/s per m]."""
    z = [float(v) for v in z]
    p = [float(v) for v in p]
    return Zpk(tuple(-v for v in z), (0.0,) + tuple(-v for v in p),
               K * float(np.prod(p) / np.prod(z)))


def prefilter(a: float, b: float, c: float) -> Zpk:
    """Eq. 4.77 structure: F(s) = (s/a + 1)/((s/b + 1)(s/c + 1)), unity DC gain."""
    return Zpk((-a,), (-b, -c), b * c / a)


def from_num_den(num, den) -> Zpk:
    """Zpk from YAML polynomials (low order only; roots must be real)."""
    num = np.trim_zeros(np.asarray(num, float), 'f')
    den = np.trim_zeros(np.asarray(den, float), 'f')
    z = np.roots(num) if len(num) > 1 else np.array([])
    p = np.roots(den)
    if np.any(np.abs(z.imag) > 1e-6 * (1 + np.abs(z.real))) or \
            np.any(np.abs(p.imag) > 1e-6 * (1 + np.abs(p.real))):
        raise ValueError('complex zeros/poles are not supported')
    z = np.where(np.abs(z.real) < 1e-9, 0.0, z.real)
    p = np.where(np.abs(p.real) < 1e-9, 0.0, p.real)
    return Zpk(tuple(float(v) for v in z), tuple(float(v) for v in p), float(num[0] / den[0]))


def pade_delay(T: float, n: int = 4) -> Zpk:
    """e^{-sT} as n cascaded first-order Pade sections (1 - s T/2n)/(1 + s T/2n): real
    zeros/poles (a cascade realisation), all-pass, phase error < 3 % for w T <= 2.5 (n = 4).
    Used only where a finite state space is needed (closed-loop eigenvalues with the delay)."""
    if T <= 0:
        return Zpk((), (), 1.0)
    a = 2.0 * n / T
    return Zpk((a,) * n, (-a,) * n, (-1.0) ** n)


# thesis controllers, eqs. 4.71, 4.76, 4.77
def thesis_velocity(k_T: float = 0.73) -> Zpk:
    """Eq. 4.71: G_v = (1/k_T)(0.45 + 56/s)/(s/2555 + 1)."""
    return velocity_controller(0.45, 56.0, 2555.0, k_T)


def thesis_position() -> Zpk:
    """Eq. 4.76: G = 2.668e9 (s+447)(s+153)(s+0.61) / (s (s+2155)(s+613)(s+522))."""
    return Zpk((-447.0, -153.0, -0.61), (0.0, -2155.0, -613.0, -522.0), 2.668e9)


def thesis_prefilter() -> Zpk:
    """Eq. 4.77: F = (s/38 + 1)/((s/77 + 1)(s/65 + 1))."""
    return prefilter(38.0, 77.0, 65.0)
