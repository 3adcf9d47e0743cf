"""Chamber pressure dynamics, eq. 3.19-3.21: capacitance beta / V with V_A,B = V_d +- A_p x."""
from numba import njit


@njit(cache=True, error_model='numpy')
def stiffness(x, V_d, A_p, beta, x_stop):
    """beta / V_A and beta / V_B (Pa per m^3); volumes use x clipped to the stroke."""
    xc = min(max(x, -x_stop), x_stop)
    return beta / (V_d + A_p * xc), beta / (V_d - A_p * xc)
