"""EhaPlant.step as one compiled call: drive delay FIFO, fault effects (faults.FaultSet.apply),
noise row and the tick kernel, with the model's Python-side state packed in arrays.

For closed-loop kernels (core.closed_loop) that advance many ticks without Python. The arrays
are a copy of that state: :func:`pack` before, :func:`unpack` after; S, U, the measurement and
the noise block are the plant's own arrays (shared, not copied).
"""
from __future__ import annotations

import math
from collections import deque

import numpy as np
from numba import njit

from ..jit_cache import drop_stale
from . import layout as L
from .integrator import tick
from .sensors import BLOCK

drop_stale(__file__)

# aux vector: time, noise row, flags, delay ring
A_T = 0          # plant time t (s)
A_TS = 1         # tick period Ts (s)
A_NOISE_K = 2    # NoiseSource.k: rows of the block already used
A_VALID = 3      # 1: every tick finite so far
A_FAULTED = 4    # EhaPlant._faulted
A_ACTIVE = 5     # active channel
A_NDELAY = 6     # delay ticks (length of the FIFO)
A_HEAD = 7       # ring index of the oldest FIFO entry
A_NFAULT = 8     # active faults (rows of the fault table)
NAUX = 9

# fault table rows: code, channel, magnitude, t_start, t_end (codes: FAULT_CODES)
FAULT_CODES = {'msp_noise': 0, 'msp_stuck': 1, 'msp_bias': 2, 'msp_drift': 3,
               'motor_fail': 4, 'pump_leakage': 5, 'pressure_sensor': 6}
F_CODE, F_CH, F_MAG, F_T0, F_T1 = range(5)
MAX_FAULTS = 16


def pack(plant):
    """(aux, delay ring, fault table) of an EhaPlant; None when faults do not fit the table."""
    if len(plant.faults.active) > MAX_FAULTS:
        return None
    aux = np.zeros(NAUX)
    aux[A_T] = plant.t
    aux[A_TS] = plant.Ts
    aux[A_NOISE_K] = plant._noise.k
    aux[A_VALID] = 1.0 if plant._valid else 0.0
    aux[A_FAULTED] = 1.0 if plant._faulted else 0.0
    aux[A_ACTIVE] = plant.active_channel
    n = plant._delay.ticks
    aux[A_NDELAY] = n
    ring = np.zeros(max(n, 1))
    ring[:n] = list(plant._delay.fifo)
    table = np.zeros((MAX_FAULTS, 5))
    for i, f in enumerate(plant.faults.active.values()):
        table[i] = (FAULT_CODES[f.name], f.channel, f.magnitude, f.t_start, f.t_end)
    aux[A_NFAULT] = len(plant.faults.active)
    return aux, ring, table


def unpack(plant, aux, ring, table) -> None:
    """Write the packed state back into the EhaPlant (the fault table is read-only)."""
    plant.t = float(aux[A_T])
    plant._noise.k = int(aux[A_NOISE_K])
    plant._valid = bool(aux[A_VALID])
    plant._faulted = bool(aux[A_FAULTED])
    n = int(aux[A_NDELAY])
    h = int(aux[A_HEAD])
    plant._delay.fifo = deque(float(v) for v in np.concatenate((ring[h:n], ring[:h])))
    if len(plant.faults.active) != int(aux[A_NFAULT]):
        raise RuntimeError('fault set changed inside a compiled segment')


@njit(cache=True)
def fault_due(aux, table) -> bool:
    """A fault expires at this tick (FaultSet.apply would delete it): Python's business."""
    t = aux[A_T]
    for i in range(int(aux[A_NFAULT])):
        if table[i, F_T1] <= t + 1e-12:
            return True
    return False


@njit(cache=True)
def apply_faults(t, U, table, n) -> None:
    """FaultSet.apply without expiry (see fault_due): fault effects into U, in dict order."""
    U[L.U_FAIL0] = 0.0
    U[L.U_FAIL1] = 0.0
    U[L.U_LEAK0] = 1.0
    U[L.U_LEAK1] = 1.0
    for j in range(L.U_FX_SIGMA, L.U_FP_STUCK + 1):
        U[j] = 0.0
    for i in range(n):
        code = int(table[i, F_CODE])
        ch = int(table[i, F_CH])
        mag = table[i, F_MAG]
        if code == 4:
            U[L.U_FAIL0 + ch] = 1.0
        elif code == 5:
            U[L.U_LEAK0 + ch] = mag
        elif code == 0:
            U[L.U_FX_SIGMA] = mag
        elif code == 2:
            U[L.U_FX_BIAS] += mag
        elif code == 3:
            U[L.U_FX_BIAS] += mag * (t - table[i, F_T0])
        elif code == 1:
            U[L.U_FX_STUCK] = 1.0
        elif code == 6:
            if math.isnan(mag):
                U[L.U_FP_STUCK] = 1.0
            else:
                U[L.U_FP_BIAS] = mag


@njit(cache=True)
def noise_exhausted(aux) -> bool:
    """The noise block is used up: NoiseSource.next_index would draw a new one (Python)."""
    return aux[A_NOISE_K] >= BLOCK


@njit(cache=True)
def step(S, P, U, T, nsub, block, meas, aux, ring, table, omega_ref, load_force) -> None:
    """EhaPlant.step with finite inputs, no fault expiring and a row left in the noise block."""
    n = int(aux[A_NDELAY])
    if n == 0:
        w = omega_ref
    else:
        h = int(aux[A_HEAD])
        w = ring[h]
        ring[h] = omega_ref
        aux[A_HEAD] = (h + 1) % n
    U[L.U_WREF] = w
    U[L.U_FL] = load_force
    nf = int(aux[A_NFAULT])
    if nf > 0 or aux[A_FAULTED] > 0.5:
        apply_faults(aux[A_T], U, table, nf)
        aux[A_FAULTED] = 1.0 if nf > 0 else 0.0
    row = int(aux[A_NOISE_K])
    aux[A_NOISE_K] = row + 1
    if not tick(S, P, U, T, nsub, block, row, meas):
        aux[A_VALID] = 0.0
    aux[A_T] += aux[A_TS]
