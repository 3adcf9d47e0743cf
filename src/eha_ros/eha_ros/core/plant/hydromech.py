"""Linear hydromechanical model of the EHA (eq. 3.20-3.23, 4.35 corrected), derived once from
the plant parameters: the load-pressure form used by the linear models (:mod:`.linear`) and the
eq. 4.35 Kalman filter, and the chamber form with the boost check valves used by the chamber
filter, with the leakage sensitivity of its ZOH.

Load-pressure form (:func:`load_pressure`; states x [m], xdot [m/s], p_D = p_A - p_B [Pa];
inputs omega [rad/s], F_L [N] along +x)::

    x'    = xdot
    xdot' = -b/m_p xdot + A_p/m_p p_D + F_L/m_p                          (eq. 3.23)
    p_D'  = -2 A_p beta/V_d xdot - k_L C beta/V_d p_D + 2 D_p beta/V_d omega   (eq. 3.22)

Chamber form (:func:`chamber`; states x, xdot, p_A, p_B [Pa gauge]; inputs omega, F_L, 1;
s_A, s_B in {0, 1}: the boost check valve of that chamber open, Fig. 3.12)::

    xdot' = (A_p (p_A - p_B) - b xdot + F_L) / m_p
    p_A'  = beta/V_d ( D_p omega - A_p xdot - C_x (p_A - p_B) - C_r (p_A - p_acc)
                       + s_A K_c (p_c - p_A))                             (eq. 3.20)
    p_B'  = beta/V_d (-D_p omega + A_p xdot + C_x (p_A - p_B) - C_r (p_B - p_acc)
                       + s_B K_c (p_c - p_B))                             (eq. 3.21)

with C_x = C_p + C_c (cross-port and cross-piston leakage), C_r the per-port leakage to the
accumulator circuit (eq. 3.15), K_c the check-valve conductance and p_c = p_acc - crack -
band/2 where the valve's linear flow line crosses zero. With both valves shut, p_A' - p_B' is
eq. 3.22's p_D row with C = C_eq = C_p + C_c + C_r/2 and k_L = 2 (the accumulator terms cancel).

Corrections to the printed equations (DESIGN.md "Known inconsistencies"; stated once, here):

- eq. 4.35 row 2 prints -A_p/m_p p_D, which makes a saddle (an unstable model); the sign is +,
  as in eq. 3.23/3.24: the load pressure pushes the piston towards +x.
- F_L enters eq. 4.35 as +F_L/m_p, a force along +x (the friction estimate of eq. 4.36); in
  eq. 3.23/3.24/3.41 and the nonlinear plant F_L pushes towards -x (-F_L/m_p).
- The p_D leakage: eq. 3.22 derives 2 C_eq beta/V_d (k_L = 2), the matrices of eq. 3.24 and
  4.35 print C_eq beta/V_d (k_L = 1). The nonlinear plant follows eq. 3.22, so k_L = 2 is the
  default. :data:`LEAKAGE` names the variants (estimator.model.pd_leakage): eq3_22 (k_L = 2,
  C = C_eq), eq4_35 (k_L = 1, as printed), boost (k_L = 2, C = C_p + C_c + C_r: the boost
  check valves hold the low-pressure chamber at the accumulator pressure, so both ports'
  external leakage C_r is drawn from the high-pressure side; the plant at constant speed shows
  5.2e-12 against C_eq = 3.8e-12).

Floating-point order (kept so that every matrix is the same to the bit as before this module):
the load-pressure rows compute 2 A_p beta / V_d from the left, the chamber rows beta/V_d first
(:attr:`Circuit.k`) and then its products.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm

from .parameters import PlantParams

LEAKAGE = ('eq3_22', 'eq4_35', 'boost')     # p_D leakage variants of the load-pressure form


@dataclass(frozen=True)
class HydroMech:
    """Constants of the load-pressure form (eq. 3.22-3.23, 4.35; SI units): C the leakage
    coefficient, leak_factor its k_L."""

    A_p: float
    m_p: float
    b: float
    beta: float
    V_d: float
    C_eq: float
    D_p: float
    leak_factor: float = 2.0


def hydromech(pp: PlantParams, leakage: str = 'eq3_22') -> HydroMech:
    """The load-pressure constants of plant ``pp`` with a p_D leakage variant of
    :data:`LEAKAGE` (module doc)."""
    if leakage not in LEAKAGE:
        raise ValueError(f'leakage {leakage!r}: expected one of {", ".join(LEAKAGE)}')
    if leakage == 'boost':
        return HydroMech(pp.A_p, pp.m_p, pp.b, pp.beta, pp.V_d, pp.C_p + pp.C_c + pp.C_r,
                         pp.D_p, 2.0)
    return HydroMech(pp.A_p, pp.m_p, pp.b, pp.beta, pp.V_d, pp.C_eq, pp.D_p,
                     2.0 if leakage == 'eq3_22' else 1.0)


def _piston_row(h, A: np.ndarray, B: np.ndarray) -> None:
    """x' = xdot and eq. 3.23 on states [x, xdot, p_A or p_D, ...], force input column 1 (+x)."""
    A[0, 1] = 1.0
    A[1, 1] = -h.b / h.m_p
    A[1, 2] = h.A_p / h.m_p
    B[1, 1] = 1.0 / h.m_p


def load_pressure(h: HydroMech, n: int = 3):
    """(A, B) of eq. 4.35 (corrected, module doc): states [x, xdot, p_D] then n - 3 zero rows
    and columns for the caller's own states, inputs [omega, F_L along +x]."""
    A = np.zeros((n, n))
    B = np.zeros((n, 2))
    _piston_row(h, A, B)
    A[2, 1] = -2.0 * h.A_p * h.beta / h.V_d
    A[2, 2] = -h.leak_factor * h.C_eq * h.beta / h.V_d
    B[2, 0] = 2.0 * h.D_p * h.beta / h.V_d
    return A, B


@dataclass(frozen=True)
class Circuit:
    """Constants of the chamber form (SI units, pressures gauge)."""

    A_p: float
    m_p: float
    b: float
    beta: float
    V_d: float
    C_x: float
    C_r: float
    D_p: float
    K_c: float
    p_acc: float
    crack: float
    band: float

    @property
    def p_c(self) -> float:
        """Zero-flow pressure of the check valve's linear flow line."""
        return self.p_acc - self.crack - 0.5 * self.band

    @property
    def k(self) -> float:
        """beta/V_d: a chamber's pressure rate per unit net flow (Pa/m^3)."""
        return self.beta / self.V_d


def circuit(pp: PlantParams) -> Circuit:
    """The chamber constants of plant ``pp`` (Fig. 3.12 boost circuit)."""
    return Circuit(pp.A_p, pp.m_p, pp.b, pp.beta, pp.V_d, pp.C_p + pp.C_c, pp.C_r, pp.D_p,
                   pp.check_K, pp.acc_p_init, pp.check_crack, pp.band)


def chamber_leakage(c: Circuit, m: int = 4, paths: str = 'xr', s_a: bool = False,
                    s_b: bool = False) -> np.ndarray:
    """A_L (m x m): the leakage part of the chamber rows of A (eq. 3.20-3.21), of the cross-port
    path C_x ('x' in ``paths``) and of the per-port path C_r ('r'), plus K_c of an open check
    valve (s_a, s_b)."""
    k = c.k
    cx = c.C_x if 'x' in paths else 0.0
    cr = c.C_r if 'r' in paths else 0.0
    AL = np.zeros((m, m))
    for i, s in ((2, s_a), (3, s_b)):
        AL[i, i] = -k * (cx + cr + (c.K_c if s else 0.0))
        AL[i, 5 - i] = k * cx
    return AL


def chamber(c: Circuit, s_a: bool, s_b: bool, n: int = 4):
    """(A, B) of the chamber form (module doc) for check-valve states s_a, s_b: states
    [x, xdot, p_A, p_B] then n - 4 zero rows and columns, inputs [omega, F_L along +x, 1]."""
    k = c.k
    A = chamber_leakage(c, n, 'xr', s_a, s_b)
    B = np.zeros((n, 3))
    _piston_row(c, A, B)
    A[1, 3] = -c.A_p / c.m_p
    for i, sign, s in ((2, 1.0, s_a), (3, -1.0, s_b)):
        A[i, 1] = -sign * k * c.A_p
        B[i, 0] = sign * k * c.D_p
        B[i, 2] = k * (c.C_r * c.p_acc + (c.K_c * c.p_c if s else 0.0))
    return A, B


def chamber_flow_columns(c: Circuit, m: int = 4) -> np.ndarray:
    """(m, 2) input columns of a unit flow (m^3/s) into chamber A and into chamber B."""
    Bq = np.zeros((m, 2))
    Bq[2, 0] = Bq[3, 1] = c.k
    return Bq


def leak_sensitivity(c: Circuit, A: np.ndarray, Ts: float, n: int,
                     paths: str = 'xr') -> np.ndarray:
    """d expm((A + s A_L) Ts)/ds at s = 0 (n x n, zero outside A's block), A_L =
    :func:`chamber_leakage` of ``paths``: lambda D is the first-order change of the ZOH F when
    those leakages are (1 + lambda) times nominal (block-triangular expm, Van Loan)."""
    m = A.shape[0]
    M = np.zeros((2 * m, 2 * m))
    M[:m, :m] = M[m:, m:] = A * Ts
    M[:m, m:] = chamber_leakage(c, m, paths) * Ts
    out = np.zeros((n, n))
    out[:m, :m] = expm(M)[:m, m:]
    return out
