"""The plant's tick as one compiled call: drive delay FIFO (drive.delay_push), fault effects
(faults.apply_faults), the noise row and the tick kernel. EhaPlant.step calls it every tick
(Python does only the rare events: a fault expiring, a new noise block), and so do the
closed-loop kernels (core.sim.closed_loop) for many ticks at once. Every array is the plant's
own, named in one record (:class:`Arrays`, EhaPlant.arrays): S, U, the measurement, the noise
block, the delay ring, the fault table and the aux vector of its scalars (A_*), so nothing is
copied back after a segment.
"""
from __future__ import annotations

from typing import NamedTuple

from numba import njit

from ..jit_cache import drop_stale
from ..kernel_records import Matrix, Vector
from . import layout as L
from .drive import delay_push
from .faults import apply_faults, expiring
from .integrator import tick
from .sensors import BLOCK

drop_stale(__file__)

# aux vector: time, noise row, flags, delay ring
NAUX = 9
(A_T,            # plant time t (s)
 A_TS,           # tick period Ts (s)
 A_NOISE_K,      # NoiseSource.k: rows of the block already used
 A_VALID,        # 1: every tick finite so far
 A_FAULTED,      # fault effects written into U at the last tick
 A_ACTIVE,       # active channel (EhaPlant.select)
 A_NDELAY,       # delay ticks (length of the FIFO)
 A_HEAD,         # ring index of the oldest FIFO entry
 A_NFAULT) = range(NAUX)     # active faults (rows of the fault table)


class Arrays(NamedTuple):
    """An EhaPlant's arrays (EhaPlant.arrays): made with the plant, never replaced (reset and
    a new noise block write into them)."""
    S: Vector           # state (layout.S_*)
    P: Vector           # constants (layout.P_*, parameters.pack)
    U: Vector           # the tick's inputs and fault effects (layout.U_*)
    T: Matrix           # pump leakage map (parameters.leakage_table)
    block: Matrix       # noise block (sensors.NoiseSource), a row per tick
    meas: Vector        # measurement (layout.M_*)
    aux: Vector         # the scalars (A_*)
    ring: Vector        # drive delay FIFO (drive.SpeedDelay)
    table: Matrix       # active faults (faults.FaultSet)
    backup: Vector      # S before the tick (integrator.tick restores it if it turned non-finite)


@njit(cache=True)
def fault_due(a) -> bool:
    """A fault expires at this tick (FaultSet.expire deletes it): Python's business."""
    return expiring(a.table, int(a.aux[A_NFAULT]), a.aux[A_T])


@njit(cache=True)
def noise_exhausted(a) -> bool:
    """The noise block is used up: NoiseSource.refill draws a new one (Python)."""
    return a.aux[A_NOISE_K] >= BLOCK


@njit(cache=True)
def step(a, nsub, omega_ref, load_force) -> None:
    """EhaPlant.step with finite inputs, no fault expiring and a row left in the noise block;
    ``a``: the plant's :class:`Arrays`, nsub its sub-steps per tick."""
    U, aux = a.U, a.aux
    U[L.U_WREF] = delay_push(a.ring, aux[A_HEAD:A_HEAD + 1], int(aux[A_NDELAY]), omega_ref)
    U[L.U_FL] = load_force
    nf = int(aux[A_NFAULT])
    if nf > 0 or aux[A_FAULTED] > 0.5:
        apply_faults(aux[A_T], U, a.table, nf)
        aux[A_FAULTED] = 1.0 if nf > 0 else 0.0
    row = int(aux[A_NOISE_K])
    aux[A_NOISE_K] = row + 1
    if not tick(a.S, a.P, U, a.T, nsub, a.block, row, a.meas, a.backup):
        aux[A_VALID] = 0.0
    aux[A_T] += aux[A_TS]
