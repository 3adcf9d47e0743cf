"""External gear pump leakage, eq. 3.15 (laminar) or volumetric-efficiency map eq. 3.31."""
from numba import njit


@njit(cache=True, error_model='numpy')
def _locate_row(T, x):
    """Bracket x in the omega grid T[1:, 0]: (row of the lower point, weight)."""
    n = T.shape[0]
    if x <= T[1, 0]:
        return 1, 0.0
    if x >= T[n - 1, 0]:
        return n - 2, 1.0
    k = 1
    while T[k + 1, 0] < x:
        k += 1
    return k, (x - T[k, 0]) / (T[k + 1, 0] - T[k, 0])


@njit(cache=True, error_model='numpy')
def _locate_col(T, x):
    """Bracket x in the p_D grid T[0, 1:]: (column of the lower point, weight)."""
    n = T.shape[1]
    if x <= T[0, 1]:
        return 1, 0.0
    if x >= T[0, n - 1]:
        return n - 2, 1.0
    k = 1
    while T[0, k + 1] < x:
        k += 1
    return k, (x - T[0, k]) / (T[0, k + 1] - T[0, k])


@njit(cache=True, error_model='numpy')
def table_coeff(T, omega, p_d):
    """Total leakage coefficient C_p + C_r from the map T (parameters.leakage_table) at
    (|omega|, |p_D|), bilinear, clamped at the grid edges."""
    i, a = _locate_row(T, abs(omega))
    j, b = _locate_col(T, abs(p_d))
    return ((1 - a) * (1 - b) * T[i, j] + a * (1 - b) * T[i + 1, j]
            + (1 - a) * b * T[i, j + 1] + a * b * T[i + 1, j + 1])


@njit(cache=True, error_model='numpy')
def leakage(C_p, C_r, use_table, T, omega, p_d, multiplier):
    """Cross-port C_p and per-port external C_r of one pump (eq. 3.15).

    With the map, the total C_p + C_r comes from eta_v (eq. 3.31) and is split in the nominal
    C_p : C_r ratio. ``multiplier`` is the pump_leakage fault.
    """
    if use_table:
        total = table_coeff(T, omega, p_d)
        share = C_p / (C_p + C_r) if C_p + C_r > 0 else 0.5
        return multiplier * share * total, multiplier * (1.0 - share) * total
    return multiplier * C_p, multiplier * C_r
