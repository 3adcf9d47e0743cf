"""Low-order controller transfer functions in zeros/poles/gain form: eqs. 4.65, 4.74, 4.77.

Responses are evaluated from the factored form; state-space realisations are cascades of real
first- and second-order sections (no high-order polynomial); num/den polynomials are only formed
for the YAML output (order <= 6)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def _split(roots):
    """Real roots and the upper members of complex-conjugate pairs (imag > 0)."""
    real = [float(np.real(r)) for r in roots if np.imag(r) == 0]
    pairs = [complex(r) for r in roots if np.imag(r) > 0]
    if len(pairs) != sum(1 for r in roots if np.imag(r) < 0):
        raise ValueError('complex zeros/poles must come in conjugate pairs')
    return real, pairs


def _sections(zeros, poles):
    """Real sections (num roots, den roots) of at most second order whose product is
    prod(s - z)/prod(s - p): conjugate pole pairs take a conjugate zero pair (or up to two real
    zeros), a conjugate zero pair left over takes two real poles, real poles take real zeros."""
    zr, zc = _split(zeros)
    pr, pc = _split(poles)
    secs = []
    for p in pc:
        if zc:
            z = zc.pop(0)
            num = [z, z.conjugate()]
        else:
            num = [zr.pop(0) for _ in range(min(2, len(zr)))]
        secs.append((num, [p, p.conjugate()]))
    while zc:
        if len(pr) < 2:
            raise ValueError('improper transfer function')
        z = zc.pop(0)
        secs.append(([z, z.conjugate()], [pr.pop(0), pr.pop(0)]))
    for p in pr:
        secs.append(([zr.pop(0)] if zr else [], [p]))
    if zr:
        raise ValueError('improper transfer function')
    return secs


@dataclass(frozen=True)
class Zpk:
    """k * prod(s - z) / prod(s - p), proper (len(z) <= len(p)); zeros and poles real or in
    complex-conjugate pairs."""

    zeros: tuple
    poles: tuple
    gain: float

    def __post_init__(self):
        if len(self.zeros) > len(self.poles):
            raise ValueError('improper transfer function')
        _split(self.zeros)                  # complex roots must come in conjugate pairs
        _split(self.poles)

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
        """(A, B, C, D): series connection of real first- and second-order sections
        (companion form each, no high-order polynomial), the gain at the output."""
        A = np.zeros((0, 0))
        B = np.zeros((0, 1))
        C = np.zeros((1, 0))
        D = np.ones((1, 1))
        for num, den in _sections(self.zeros, self.poles):
            a = np.real(np.poly(den))                       # monic, degree m = 1 or 2
            b = np.real(np.poly(num)) if num else np.ones(1)
            m = len(a) - 1
            b = np.concatenate([np.zeros(m + 1 - len(b)), b])
            d = b[0]
            Ai = np.zeros((m, m))
            Ai[0, :] = -a[1:]
            Ai[1:, :-1] = np.eye(m - 1)
            Bi = np.zeros((m, 1))
            Bi[0, 0] = 1.0
            Ci = (b[1:] - d * a[1:])[None, :]
            # series: this section after (A, B, C, D)
            n = A.shape[0]
            An = np.zeros((n + m, n + m))
            An[:n, :n] = A
            An[n:, :n] = Bi @ C
            An[n:, n:] = Ai
            B = np.vstack([B, Bi @ D])
            C = np.hstack([d * C, Ci])
            D = d * D
            A = An
        return A, B, self.gain * C, self.gain * D

    def num_den(self):
        """Polynomial coefficients in descending powers of s (for the controller YAML)."""
        num = self.gain * np.real(np.poly(np.asarray(self.zeros, complex))) if self.zeros else \
            np.array([self.gain])
        den = np.real(np.poly(np.asarray(self.poles, complex)))
        return [float(v) for v in np.atleast_1d(num)], [float(v) for v in np.atleast_1d(den)]


def velocity_controller(K1: float, K2: float, K3: float, k_T: float) -> Zpk:
    """Eq. 4.65: G_v(s) = (1/k_T)(K1 + K2/s) / (s/K3 + 1)  [A per rad/s]."""
    return Zpk((-K2 / K1,), (0.0, -K3), K1 * K3 / k_T)


def position_controller(K: float, z, p, biquads=()) -> Zpk:
    """Eq. 4.74: G(s) = K/s prod (1 + s/z_i)/(1 + s/p_i)  [rad/s per m], times optional
    second-order sections (s^2/wz^2 + 2 zz s/wz + 1)/(s^2/wp^2 + 2 zp s/wp + 1) given as
    (wz, zz, wp, zp) (unity DC gain; complex pairs for zeta < 1)."""
    z = [float(v) for v in z]
    p = [float(v) for v in p]
    zeros = [complex(-v) for v in z]
    poles = [0j] + [complex(-v) for v in p]
    k = K * float(np.prod(p) / np.prod(z))
    for wz, zz, wp, zp in biquads:
        zeros += list(np.roots([1.0, 2.0 * zz * wz, wz * wz]).astype(complex))
        poles += list(np.roots([1.0, 2.0 * zp * wp, wp * wp]).astype(complex))
        k *= (wp / wz) ** 2
    return Zpk(tuple(_tidy(zeros)), tuple(_tidy(poles)), k)


def _tidy(roots):
    """Roots with a negligible imaginary part as real floats (the rest stay complex)."""
    return [r.real if abs(r.imag) <= 1e-9 * (1.0 + abs(r.real)) else r
            for r in (complex(v) for v in roots)]


def prefilter(a: float, b: float, c: float) -> Zpk:
    """Eq. 4.77 structure: F(s) = (s/a + 1)/((s/b + 1)(s/c + 1)), unity DC gain."""
    return Zpk((-a,), (-b, -c), b * c / a)


def from_num_den(num, den) -> Zpk:
    """Zpk from YAML polynomials (low order; complex roots must come in conjugate pairs)."""
    num = np.trim_zeros(np.asarray(num, float), 'f')
    den = np.trim_zeros(np.asarray(den, float), 'f')
    z = np.roots(num) if len(num) > 1 else np.array([])
    p = np.roots(den)
    z = [0.0 if abs(v) < 1e-9 else v for v in _tidy(z)]
    p = [0.0 if abs(v) < 1e-9 else v for v in _tidy(p)]
    return Zpk(tuple(z), tuple(p), float(num[0] / den[0]))


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
