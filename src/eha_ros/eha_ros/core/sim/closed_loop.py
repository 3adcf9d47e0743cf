"""The stack's tick, compiled (DESIGN.md "three ways", 3): plant, estimator, position
controller and switch-manager health checks in the stack's order state(k) -> estimate(k) ->
command(k) (+ channel select(k)) -> applied by the plant at k+1.

One loop body: the tick is :func:`segment`'s, run for many ticks in one call and for one
(``segment(k, k + 1, ...)``) by core.sim.batch.BatchLoop.tick; :func:`record` writes a tick's
row, for it and for the Python tick. Each tick runs the components' compiled steppers
(plant.stepper, estimator.stepper, controller.stepper, redundancy.stepper): the same
operations as the Python objects, so the results are bit-identical. A tick that anything
event-like would touch -- a fault expiring, a measurement to reject, a valve step of a
switch, a monitor verdict the state machine must act on, a non-finite value -- is not done
here: the segment stops *before* it (components rolled back to the tick's start) and returns
EVENT and its index, for BatchLoop to do that tick with the Python objects. So the compiled
tick never gives an answer the Python one would not.

(A separate ``tick`` function called by the segment loop, inlined or not, measured 15-20 %
slower per tick than this one loop body, 2026-11-27.)
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..controller import stepper as CS
from ..estimator import adapt as EA
from ..estimator import stepper as ES
from ..jit_cache import drop_stale
from ..plant import layout as L
from ..plant import stepper as PS
from ..redundancy import stepper as RS

drop_stale(__file__, '.', '../plant', '../estimator', '../controller', '../redundancy', '../loop')

END, EVENT, NOISE = 0, 1, 2          # why a segment returned
# record columns, one row per tick
R_T = 0          # plant time after the step (s)
R_X = 1          # true position after the step (m)
R_X0 = 2         # true position at the tick start, when the state was measured (m)
R_XM = 3         # measured position (m)
R_XHAT = 4       # estimate (m)
R_U = 5          # motor speed command (rad/s)
R_NIS = 6
R_INNOV = 7      # position innovation (m)
R_FAULT = 8      # estimator sensor fault code
R_NISDIM = 9
R_W = 10         # true motor speeds after the step (2)
R_WM = 12        # measured motor speeds (2)
R_I = 14         # true motor currents after the step (2)
R_VALVE = 16     # valve opening fractions after the step (2)
R_BYPASS = 18
R_EN = 19        # drive enables (2)
R_CHANNEL = 21   # plant's active channel when measured
R_ACTIVE = 22    # switch manager's active channel after its update
R_STATE = 23     # switch manager's state code (ACTIVE_A 0, ACTIVE_B 1, SWITCHING 2,
                 # DEGRADED 3, FAILED_SAFE 4)
R_PM = 24        # measured pressures p_A, p_B (Pa)
R_IM = 26        # measured motor currents (2)
R_V0 = 28        # true velocity at the tick start (m/s)
R_VHAT = 29      # estimated velocity (m/s)
R_VERDICT = 30   # estimator consistency verdict (adapt.VERDICTS)
R_SKIP = 31      # 1: the estimator skipped this update
R_P = 32         # true chamber pressures p_A, p_B after the step (Pa)
R_GM = 34        # the position sensor's Gauss-Markov offset in the measured position (m)
NREC = 35


@njit(cache=True)
def _copy(src, dst):
    """dst <- src (same shape, 1 to 3 dimensions), no allocation."""
    if src.ndim == 1:
        for i in range(src.shape[0]):
            dst[i] = src[i]
    elif src.ndim == 2:
        for i in range(src.shape[0]):
            for j in range(src.shape[1]):
                dst[i, j] = src[i, j]
    else:
        for i in range(src.shape[0]):
            for j in range(src.shape[1]):
                for m in range(src.shape[2]):
                    dst[i, j, m] = src[i, j, m]


@njit(cache=True)
def state_code(g) -> int:
    st = int(g[RS.G_STATE])
    if st == RS.ST_ACTIVE:
        return int(g[RS.G_ACTIVE])
    return 2 if st == RS.ST_SWITCHING else (3 if st == RS.ST_DEGRADED else 4)


@njit(cache=True, inline='always')
def record(r, plant, x0, v0, gm0, pos, w_meas, i_meas, pa, pb, ch, x_hat, v_hat, u, nis,
           innov, code, nd, verdict, skip, active, state) -> None:
    """A tick's record row ``r`` (R_* columns), the one place it is written: the plant's
    state after the step from its arrays, the rest as the tick measured (at its start),
    estimated and commanded."""
    S, U = plant.S, plant.U
    r[R_T] = plant.aux[PS.A_T]
    r[R_X] = S[L.S_X]
    r[R_X0] = x0
    r[R_XM] = pos
    r[R_XHAT] = x_hat
    r[R_U] = u
    r[R_NIS] = nis
    r[R_INNOV] = innov
    r[R_FAULT] = code
    r[R_NISDIM] = nd
    for c in range(2):
        b = L.S_CH + c * L.NCH
        r[R_W + c] = S[b + L.C_W]
        r[R_WM + c] = w_meas[c]
        r[R_I + c] = S[b + L.C_I]
        r[R_IM + c] = i_meas[c]
        r[R_VALVE + c] = S[b + L.C_FV]
        r[R_EN + c] = U[L.U_EN0 + c] > 0.5
        r[R_P + c] = S[L.S_PA + c]
    r[R_PM] = pa
    r[R_PM + 1] = pb
    r[R_V0] = v0
    r[R_GM] = gm0
    r[R_VHAT] = v_hat
    r[R_VERDICT] = verdict
    r[R_SKIP] = skip
    r[R_BYPASS] = S[L.S_FB]
    r[R_CHANNEL] = ch
    r[R_ACTIVE] = active
    r[R_STATE] = state


@njit(cache=True)
def segment(k0, k1, off, Ts, refs, loads, plant, nsub, est, has_est, ctl, mgr, has_mgr, u,
            rec):
    """Ticks k0 .. k1-1 with refs[k - off], loads[k - off] into rec[k - off]; u is the
    previous command (rad/s); ``plant``: the plant's plant.stepper.Arrays, nsub its sub-steps.

    Returns (k, why, u): k the first tick not done (k1 at END), why END / EVENT (tick k is
    Python's) / NOISE (draw the next noise block, call again), u the last command.
    """
    S, U, meas, aux = plant.S, plant.U, plant.meas, plant.aux
    ek, ee, ea = est                    # estimator stepper: constants K, state E, Arrays
    ck, cc, ca = ctl                    # controller stepper: constants, state, Arrays
    x, Pe, Q, Fx, Gx = ea.x, ea.P, ea.Q, ca.Fx, ca.Gx
    ms, hs, g = mgr.ms, mgr.hs, mgr.g   # switch manager stepper: Arrays
    keep = (x.copy(), Pe.copy(), ee.copy(), cc.copy(), Fx.copy(), Gx.copy(), ms.copy(),
            hs.copy(), g.copy(), Q.copy())
    w_meas = np.zeros(2)
    i_meas = np.zeros(2)
    reported = np.zeros(2, np.bool_)
    fault = np.zeros(2, np.bool_)
    steady = np.zeros(2, np.bool_)
    cmd = np.zeros(2, np.bool_)
    age = np.zeros(2)
    for k in range(k0, k1):
        if PS.noise_exhausted(plant):
            return k, NOISE, u
        ref = refs[k - off]
        load = loads[k - off]
        pos = meas[L.M_X]
        ch = int(aux[PS.A_ACTIVE])
        pa = meas[L.M_PA]
        pb = meas[L.M_PB]
        if (PS.fault_due(plant) or not math.isfinite(load) or not CS.ready(cc, ref)
                or (has_est and not ES.ready(ek, ee, pos, meas[L.M_W0 + ch], pa, pb))):
            return k, EVENT, u
        _copy(x, keep[0]); _copy(Pe, keep[1]); _copy(ee, keep[2]); _copy(cc, keep[3])  # noqa
        _copy(Fx, keep[4]); _copy(Gx, keep[5]); _copy(ms, keep[6]); _copy(hs, keep[7])  # noqa
        _copy(g, keep[8]); _copy(Q, keep[9])  # noqa (Q: the estimator's adaptive noise levels)
        for c in range(2):
            w_meas[c] = meas[L.M_W0 + c]
            i_meas[c] = meas[L.M_I0 + c]
            reported[c] = U[L.U_EN0 + c] > 0.5
            fault[c] = U[L.U_FAIL0 + c] > 0.5
        x0 = S[L.S_X]
        v0 = S[L.S_V]
        gm0 = S[L.S_GM]
        w_act = meas[L.M_W0 + ch]
        if has_est:
            x_hat, innov, nis, nd, code = ES.estimate(ek, ee, ea, pos, w_act,
                                                      meas[L.M_I0 + ch], pa, pb)
            w_act = ee[0].omega             # the estimate's motor speed, as in EstimateResult
        else:
            x_hat, innov, nis, nd, code = pos, math.nan, math.nan, 0, 0
        CS.request(ck, cc, ref)
        # a position fault (core.loop.safe_state) is Python's: rolled back, then done by BatchLoop
        ok = math.isfinite(x_hat) and not (has_est and ES.position_fault(ee))
        if ok and has_mgr:
            ok = RS.supervise(mgr, k * Ts, k, u, u, True, w_meas, i_meas, pa, pb, reported,
                              fault, innov, nd > 0 and code == 0, steady, age, cmd)
        un = math.nan
        if ok:
            un = CS.control(ck, cc, ca, x_hat, w_act,
                            ES.leak_flow(ek, x) if has_est else math.nan)
        if not math.isfinite(un):
            _copy(keep[0], x); _copy(keep[1], Pe); _copy(keep[2], ee); _copy(keep[3], cc)  # noqa
            _copy(keep[4], Fx); _copy(keep[5], Gx); _copy(keep[6], ms); _copy(keep[7], hs)  # noqa
            _copy(keep[8], g); _copy(keep[9], Q)  # noqa
            return k, EVENT, u
        PS.step(plant, nsub, un, load)
        u = un
        record(rec[k - off], plant, x0, v0, gm0, pos, w_meas, i_meas, pa, pb, ch, x_hat,
               x[1] if has_est else math.nan, un, nis, innov, code, nd,
               ee[0].monitor[EA.MS_VERDICT] if has_est else 0, 1 if has_est and nd == 0 else 0,
               g[RS.G_ACTIVE] if has_mgr else ch, state_code(g) if has_mgr else ch)
    return k1, END, u
