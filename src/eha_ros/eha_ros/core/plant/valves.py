"""Check, relief, on-off and bypass valves of the redundant circuit (Fig. 3.12), linear orifices.

Check and relief valves open linearly above their cracking pressure, with a quadratic
transition of width ``band`` (Pa) so that the flow has a continuous derivative: Newton then
converges quadratically instead of cycling on the kink (a real poppet opens gradually too).
"""
from numba import njit


@njit(cache=True, error_model='numpy')
def smooth_ramp(dp, K, band):
    """K * max(dp, 0) with a C1 quadratic corner over [0, band]: (flow, d flow / d dp)."""
    if dp <= 0.0:
        return 0.0, 0.0
    if dp < band:
        return K * dp * dp / (2.0 * band), K * dp / band
    return K * (dp - 0.5 * band), K


@njit(cache=True, error_model='numpy')
def check_flow(p_acc, p_chamber, K, crack, band):
    """Check valve accumulator -> chamber: flow and d(flow)/d(p_chamber)."""
    q, dq = smooth_ramp(p_acc - p_chamber - crack, K, band)
    return q, -dq


@njit(cache=True, error_model='numpy')
def relief_flow(p_chamber, p_low, K, crack, band):
    """Relief valve chamber -> low-pressure circuit, cracking at p_low + crack (Table 3.2)."""
    return smooth_ramp(p_chamber - p_low - crack, K, band)


@njit(cache=True, error_model='numpy')
def ramp(fraction, target, rate):
    """On-off valve opening fraction: linear ramp towards target (0 or 1), rate per sub-step."""
    if fraction < target:
        return min(target, fraction + rate)
    if fraction > target:
        return max(target, fraction - rate)
    return fraction
