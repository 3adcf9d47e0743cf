"""Batched frequency responses C (jwI - A)^-1 B + D from state space (eq. 3.36, 3.42).

Never via ss2tf: high-order polynomial numerators lose all accuracy without slycot."""
from __future__ import annotations

import numpy as np


def ss_freqresp(A, B, C, w, D=None) -> np.ndarray:
    """SISO responses of a batch of systems.

    A: (N, n, n); B: (N, n) or (n,); C: (N, n) or (n,); w: (F,) rad/s -> (N, F) complex.
    """
    A = np.asarray(A, float)
    if A.ndim == 2:
        A = A[None]
    N, n, _ = A.shape
    w = np.atleast_1d(np.asarray(w, float))
    B = np.broadcast_to(np.asarray(B, float).reshape(-1, n), (N, n))
    C = np.broadcast_to(np.asarray(C, float).reshape(-1, n), (N, n))
    M = (1j * w)[None, :, None, None] * np.eye(n) - A[:, None, :, :]          # (N, F, n, n)
    rhs = np.broadcast_to(B[:, None, :, None], (N, len(w), n, 1)).astype(complex)
    X = np.linalg.solve(M, rhs)[..., 0]                                       # (N, F, n)
    H = np.einsum('nk,nfk->nf', C, X)
    if D is not None:
        H = H + np.asarray(D, float).reshape(-1, 1)
    return H


def feedback(Ap, Bp, Cp, ctrl, extra_B=()):
    """Unity negative feedback of a batch of SISO plants with a controller (A, B, C, D).

    u = G (r - y), y = Cp x. Returns (A_cl, B_r, [B_extra...]) with states [x_plant, x_ctrl];
    output rows of the plant are padded with zeros by :func:`pad`.
    """
    Ac, Bc, Cc, Dc = (np.asarray(v, float) for v in ctrl)
    Ap = np.asarray(Ap, float)
    N, n, _ = Ap.shape
    m = Ac.shape[0]
    Bp = np.asarray(Bp, float).reshape(N, n)
    Cp = np.asarray(Cp, float).reshape(N, n)
    dc = float(Dc[0, 0])
    A = np.zeros((N, n + m, n + m))
    A[:, :n, :n] = Ap - dc * Bp[:, :, None] * Cp[:, None, :]
    A[:, :n, n:] = Bp[:, :, None] * Cc[0][None, None, :]
    A[:, n:, :n] = -Bc[None, :, 0:1] * Cp[:, None, :]
    A[:, n:, n:] = Ac[None]
    Br = np.concatenate([dc * Bp, np.broadcast_to(Bc[:, 0], (N, m))], axis=1)
    extras = [np.concatenate([np.asarray(b, float).reshape(N, n), np.zeros((N, m))], axis=1)
              for b in extra_B]
    return A, Br, extras


def pad(C, m):
    """Output rows extended by m zero columns (controller states)."""
    C = np.asarray(C, float)
    return np.concatenate([C, np.zeros(C.shape[:-1] + (m,))], axis=-1)


def max_real_eig(A) -> np.ndarray:
    """Largest real part of the eigenvalues of each matrix of a batch (closed-loop stability)."""
    return np.max(np.linalg.eigvals(A).real, axis=-1)
