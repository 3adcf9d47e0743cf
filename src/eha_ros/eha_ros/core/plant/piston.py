"""Piston mechanics, eq. 3.32, with end stops at +-stroke/2 (stiff spring-damper)."""
from numba import njit


@njit(cache=True, error_model='numpy')
def end_stop(x, v, x_stop, k, c):
    """End-stop force (along +x) and its partials (dF/dx, dF/dv).

    Only while penetrating; the damper cannot pull the piston into the stop (force >= 0
    pushing back out).
    """
    if x > x_stop:
        f = -k * (x - x_stop) - c * v
        if f < 0.0:
            return f, -k, -c
        return 0.0, 0.0, 0.0
    if x < -x_stop:
        f = -k * (x + x_stop) - c * v
        if f > 0.0:
            return f, -k, -c
        return 0.0, 0.0, 0.0
    return 0.0, 0.0, 0.0
