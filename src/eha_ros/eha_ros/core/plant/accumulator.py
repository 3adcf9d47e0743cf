"""Gas-charged accumulator, isothermal gas law P_g V_g = P_0 V_0 (eq. 3.18), absolute pressures."""
from numba import njit


@njit(cache=True, error_model='numpy')
def pressure(v_oil, V_0, P_0, p_atm):
    """Gauge pressure for an oil volume v_oil in an accumulator of gas volume V_0 at P_0 (gauge)."""
    v_gas = V_0 - v_oil
    if v_gas < 0.05 * V_0:
        v_gas = 0.05 * V_0
    return (P_0 + p_atm) * V_0 / v_gas - p_atm


def oil_volume(p, V_0, P_0, p_atm):
    """Oil volume at gauge pressure p (inverse of :func:`pressure`)."""
    if p <= P_0:
        return 0.0
    return V_0 - (P_0 + p_atm) * V_0 / (p + p_atm)
