"""The Kalman kernels' structured products (core.estimator.kernels.sandwich): the same bits as
the dense products they replace, on matrices shaped like the estimator's and on random sparse
ones."""
import numpy as np
import pytest
from numba import njit

from eha_ros.core.estimator import kernels as K


@njit(cache=False)
def dense_propagate(F, P, Q, tmp):
    """P <- F P F' + Q with the dense products (the kernel before the structured one)."""
    K.mul(F, P, tmp, None, False, False, False)
    K.mul(tmp, F, P, Q, False, True, True)


def _sparse_like_estimator(n: int, rng) -> np.ndarray:
    """A transition matrix with the estimator's shape: a dense 4 x 4 model block, a diagonal
    elsewhere, a few parameter columns coupling into the model block, exact zeros elsewhere."""
    F = np.zeros((n, n))
    F[:4, :4] = rng.normal(size=(4, 4)) * 0.3 + np.eye(4)
    F[np.arange(4, n), np.arange(4, n)] = 1.0 - rng.uniform(0.0, 1e-3, n - 4)
    for col in rng.choice(np.arange(4, n), size=min(3, n - 4), replace=False):
        F[:4, col] = rng.normal(size=4) * 1e-4
    return F


def _spd(n: int, rng) -> np.ndarray:
    A = rng.normal(size=(n, n))
    return A @ A.T + n * np.eye(n)


@pytest.mark.parametrize('n', [3, 4, 8, 12])
def test_propagate_is_the_dense_product_to_the_bit(n):
    rng = np.random.default_rng(n)
    for _ in range(20):
        F = _sparse_like_estimator(n, rng) if n > 4 else rng.normal(size=(n, n))
        P = _spd(n, rng)
        Q = np.diag(rng.uniform(0.0, 1.0, n))
        Pd, Ps = P.copy(), P.copy()
        dense_propagate(F, Pd, Q, np.empty((n, n)))
        K.propagate(F, Ps, Q, K.scratch(n))
        assert np.array_equal(Pd, Ps)
        assert np.array_equal(Ps, Ps.T)
        Pn = P.copy()
        K.propagate(F, Pn, Q, np.empty((n, n)))     # plain n x n scratch: allocates the rest
        assert np.array_equal(Pn, Pd)
    assert np.count_nonzero(F) < n * n or n <= 4     # the pattern really skips terms


@njit(cache=False)
def dense_joseph(x, P, H, R, z):
    """Joseph update with dense products only (the kernel's arithmetic before sandwich)."""
    n, m = x.shape[0], z.shape[0]
    PHt = np.empty((n, m))
    S = np.empty((m, m))
    K_ = np.empty((n, m))
    KR = np.empty((n, m))
    y = np.empty(m)
    IKH = np.empty((n, n))
    T = np.empty((n, n))
    dx = np.empty(n)
    K.mul(P, H, PHt, None, False, True, False)
    K.mulv(H, x, y, z, True)
    K.mul(H, PHt, S, R, False, False, False)
    Si = np.linalg.inv(S)
    K.mul(PHt, Si, K_, None, False, False, False)
    K.mulv(K_, y, dx, None, False)
    for i in range(n):
        x[i] += dx[i]
    for i in range(n):
        for j in range(n):
            IKH[i, j] = 1.0 if i == j else 0.0
    K.mul(K_, H, IKH, IKH, True, False, False)
    K.mul(IKH, P, T, None, False, False, False)
    K.mul(K_, R, KR, None, False, False, False)
    K.mul(T, IKH, P, None, False, True, True)
    K.mul(KR, K_, P, P, False, True, True)


def _same_bits_as_dense(H, rng):
    """One Joseph update of a random state through the kernel and through dense_joseph:
    the same x and P to the bit."""
    m, n = H.shape
    x = rng.normal(size=n)
    P = _spd(n, rng)
    R = np.diag(rng.uniform(0.1, 1.0, m))
    z = rng.normal(size=m)
    xd, Pd, xs, Ps = x.copy(), P.copy(), x.copy(), P.copy()
    dense_joseph(xd, Pd, H, R, z)
    K.update(xs, Ps, H, R, z, np.empty(m), np.empty((m, m)))
    assert np.array_equal(xd, xs)
    assert np.array_equal(Pd, Ps)


@pytest.mark.parametrize('n,m', [(3, 1), (4, 2), (12, 3), (12, 1)])
def test_joseph_update_is_the_dense_one_to_the_bit(n, m):
    rng = np.random.default_rng(10 * n + m)
    H = np.zeros((m, n))
    H[0, 0] = 1.0
    if n > 3:
        H[0, 3] = 1.0                       # position = x + sensor offset
    for j in range(1, m):
        H[j, 1 + j] = 1.0                   # pressures
    for _ in range(20):
        _same_bits_as_dense(H, rng)


@pytest.mark.parametrize('n,m', [(5, 2), (12, 3)])
def test_joseph_update_over_any_sparse_h_is_the_dense_one_to_the_bit(n, m):
    """Random sparse H (about 30 % of the entries, values other than 1, rows of several
    entries, columns shared by rows, empty columns): I - K H is I but in H's columns, and the
    sandwich over its pattern keeps the dense bits."""
    rng = np.random.default_rng(7 * n + m)
    for _ in range(30):
        H = np.where(rng.uniform(size=(m, n)) < 0.3, rng.normal(size=(m, n)), 0.0)
        H[0, n - 1] = 2.5                   # the last column always used
        H[m - 1, 0] = -0.7
        _same_bits_as_dense(H, rng)
    assert np.count_nonzero(H) < m * n             # I - K H really has zeros to skip


@njit(cache=False)
def numpy_inv(S):
    return np.linalg.inv(S)


@pytest.mark.parametrize('m', [1, 2, 3])
def test_inverse_is_np_linalg_inv_to_the_bit(m):
    """kernels.inverse makes np.linalg.inv's LAPACK calls on the update's scratch (no
    allocation): the same bits on innovation covariances of the estimator's scales (position
    in m^2, pressures in Pa^2, correlated), and its errors."""
    rng = np.random.default_rng(m)
    Sinv, ipiv = np.empty(m * m), np.empty(m, np.int32)
    for _ in range(500):
        C = rng.normal(size=(m, m))
        d = 10.0 ** rng.uniform(-6, 6, size=m)
        S = d[:, None] * (C @ C.T + 0.5 * np.eye(m)) * d[None, :]
        K.inverse(S, Sinv, ipiv)
        assert np.array_equal(Sinv.reshape(m, m).T, numpy_inv(S))
    S[0, 0] = np.nan
    with pytest.raises(np.linalg.LinAlgError, match='infs or NaNs'):
        K.inverse(S, Sinv, ipiv)
    with pytest.raises(np.linalg.LinAlgError, match='singular'):
        K.inverse(np.zeros((m, m)), Sinv, ipiv)
