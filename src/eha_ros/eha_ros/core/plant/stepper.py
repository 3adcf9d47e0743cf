"""The plant's tick as one compiled call: drive delay FIFO (drive.delay_push), fault effects
(faults.apply_faults), the noise row and the tick kernel. EhaPlant.step calls it every tick
(Python does only the rare events: a fault expiring, a new noise block), and so do the
closed-loop kernels (core.sim.closed_loop) for many ticks at once. Every array is the plant's
own: S, U, the measurement, the noise block, the delay ring, the fault table and the aux
vector of its scalars (A_*), so nothing is copied back after a segment.
"""
from __future__ import annotations

from numba import njit

from ..jit_cache import drop_stale
from . import layout as L
from .drive import delay_push
from .faults import apply_faults, expiring
from .integrator import tick
from .sensors import BLOCK

drop_stale(__file__)

# aux vector: time, noise row, flags, delay ring
A_T = 0          # plant time t (s)
A_TS = 1         # tick period Ts (s)
A_NOISE_K = 2    # NoiseSource.k: rows of the block already used
A_VALID = 3      # 1: every tick finite so far
A_FAULTED = 4    # fault effects written into U at the last tick
A_ACTIVE = 5     # active channel
A_NDELAY = 6     # delay ticks (length of the FIFO)
A_HEAD = 7       # ring index of the oldest FIFO entry
A_NFAULT = 8     # active faults (rows of the fault table)
NAUX = 9


def pack(plant):
    """(aux, delay ring, fault table) of an EhaPlant: its own arrays (the active channel
    written into aux)."""
    aux = plant._aux
    aux[A_ACTIVE] = plant.active_channel
    return aux, plant._delay.ring, plant.faults.table


@njit(cache=True)
def fault_due(aux, table) -> bool:
    """A fault expires at this tick (FaultSet.expire deletes it): Python's business."""
    return expiring(table, int(aux[A_NFAULT]), aux[A_T])


@njit(cache=True)
def noise_exhausted(aux) -> bool:
    """The noise block is used up: NoiseSource.refill draws a new one (Python)."""
    return aux[A_NOISE_K] >= BLOCK


@njit(cache=True)
def step(S, P, U, T, nsub, block, meas, aux, ring, table, omega_ref, load_force) -> None:
    """EhaPlant.step with finite inputs, no fault expiring and a row left in the noise block."""
    U[L.U_WREF] = delay_push(ring, aux[A_HEAD:A_HEAD + 1], int(aux[A_NDELAY]), omega_ref)
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
