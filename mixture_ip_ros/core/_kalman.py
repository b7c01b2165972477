"""Compiled inner loops of the online estimator: one observation, every hypothesis
(kalman_update), and the mean trajectory that a robot command needs (mean_trajectory).

Per hypothesis h the observed-agent weights have N(mu_h, Sigma_h); the observation
y = (I_P kron psi_h^T) w + e, e ~ N(0, diag(noise)). The update factors S = L L^T (P x P) and
applies G = L^-1 H Sigma, Sigma -= G^T G, which keeps Sigma positive definite over thousands
of updates (the textbook K H Sigma form drifts). Cost O(P d^2) per hypothesis.

Layout: the hypotheses are the fastest-varying index of every state array, so each inner loop
runs over hypotheses with unit stride (SIMD over hypotheses; a row of d = 45 entries left a
scalar remainder in every loop and ten times fewer iterations per loop entry), and Sigma is
stored as its lower triangle only (symmetric by construction, half the update and memory):
entry (i, j), j <= i, of hypothesis h is cov[i (i + 1) / 2 + j, h]. The first n columns are
the hypotheses still tracked (see OnlineEstimator's pruning).
"""

import numba
import numpy as np

_LOG_2PI = float(np.log(2.0 * np.pi))


@numba.njit(cache=True, fastmath=False, boundscheck=False)
def basis_rows(z, centers, width):
    """psi(z) of GaussianBasis (clamped to [0, 1]) for each phase in z: (M, N)."""
    M, N = z.shape[0], centers.shape[0]
    out = np.empty((M, N))
    inv = 0.5 / (width * width)
    for m in range(M):
        zc = min(max(z[m], 0.0), 1.0)
        s = 0.0
        for n in range(N):
            e = zc - centers[n]
            out[m, n] = np.exp(-e * e * inv)
            s += out[m, n]
        for n in range(N):
            out[m, n] /= s
    return out


def tri_index(d):
    """(d, d) positions of Sigma[i, j] in the packed lower triangle (both halves)."""
    i, j = np.indices((d, d))
    hi, lo = np.maximum(i, j), np.minimum(i, j)
    return hi * (hi + 1) // 2 + lo


@numba.njit(cache=True, inline='always')
def _tri(i, j):
    return i * (i + 1) // 2 + j if j <= i else j * (j + 1) // 2 + i


# 'contract' only: multiply-adds fused, no reassociation (results do not depend on the order
# of the hypotheses or on how many are tracked).
@numba.njit(cache=True, fastmath={'contract'}, boundscheck=False)
def kalman_update(cov, mu, loglik, psi, psi_index, y, noise, n):
    """In place, for the first ``n`` columns: Sigma and mu conditioned on ``y`` (eq. 4 in
    Kalman form) and loglik += log N(y; H mu, H Sigma H^T + R) (the factor of eq. 18).

    cov (d (d + 1) / 2, H) packed lower triangles, mu (d, H), loglik (H,); ``psi`` (M, N) basis
    rows per phase hypothesis, ``psi_index`` (H,) which row each column uses; noise (P,) = diag R.
    """
    d = mu.shape[0]
    P = y.shape[0]
    N = psi.shape[1]
    phi = np.empty((N, n))
    for h in range(n):
        row = psi[psi_index[h]]
        for k in range(N):
            phi[k, h] = row[k]
    n_rows = -(-P // 3) * 3         # G in groups of three rows (the extra rows stay zero)
    G = np.zeros((n_rows, d, n))
    L = np.empty((P, P, n))
    r = np.empty((P, n))
    # H Sigma: row p is sum_k psi_k Sigma[pN + k, :], three basis rows per pass.
    for p in range(P):
        for j in range(d):
            out = G[p, j]
            k = 0
            while k < N:
                i0 = p * N + k
                if k + 3 <= N:
                    s0, s1, s2 = cov[_tri(i0, j)], cov[_tri(i0 + 1, j)], cov[_tri(i0 + 2, j)]
                    f0, f1, f2 = phi[k], phi[k + 1], phi[k + 2]
                    for h in range(n):
                        out[h] += f0[h] * s0[h] + f1[h] * s1[h] + f2[h] * s2[h]
                    k += 3
                else:
                    s0, f0 = cov[_tri(i0, j)], phi[k]
                    for h in range(n):
                        out[h] += f0[h] * s0[h]
                    k += 1
    # S = H Sigma H^T + R (lower half) and the residual y - H mu.
    for p in range(P):
        for q in range(p + 1):
            out = L[p, q]
            for h in range(n):
                out[h] = 0.0
            for k in range(N):
                a, f = G[p, q * N + k], phi[k]
                for h in range(n):
                    out[h] += a[h] * f[h]
        out = L[p, p]
        for h in range(n):
            out[h] += noise[p]
        out = r[p]
        for h in range(n):
            out[h] = y[p]
        for k in range(N):
            m, f = mu[p * N + k], phi[k]
            for h in range(n):
                out[h] -= f[h] * m[h]
    # S = L L^T in place.
    for i in range(P):
        for j in range(i + 1):
            out = L[i, j]
            for q in range(j):
                a, b = L[i, q], L[j, q]
                for h in range(n):
                    out[h] -= a[h] * b[h]
            if i == j:
                for h in range(n):
                    out[h] = np.sqrt(out[h])
            else:
                b = L[j, j]
                for h in range(n):
                    out[h] /= b[h]
    # G = L^-1 H Sigma in place, whitened residual r = L^-1 (y - H mu), log det S.
    inv = np.empty(n)
    logdet = np.zeros(n)
    prod = np.ones(n)
    for p in range(P):
        b = L[p, p]
        for h in range(n):
            inv[h] = 1.0 / b[h]
            prod[h] *= b[h]
        if p % 8 == 7 or p == P - 1:    # L_pp^2 >= min(noise): 8 factors cannot underflow
            for h in range(n):
                logdet[h] += 2.0 * np.log(prod[h])
                prod[h] = 1.0
        for q in range(p):
            a = L[p, q]
            for j in range(d):
                out, g = G[p, j], G[q, j]
                for h in range(n):
                    out[h] -= a[h] * g[h]
            out, g = r[p], r[q]
            for h in range(n):
                out[h] -= a[h] * g[h]
        for j in range(d):
            out = G[p, j]
            for h in range(n):
                out[h] *= inv[h]
        out = r[p]
        for h in range(n):
            out[h] *= inv[h]
    c = P * _LOG_2PI
    for h in range(n):
        quad = 0.0
        for p in range(P):
            quad += r[p, h] * r[p, h]
        loglik[h] += -0.5 * (c + logdet[h] + quad)
    # mu += G^T r
    for i in range(d):
        out = mu[i]
        for p in range(P):
            a, b = G[p, i], r[p]
            for h in range(n):
                out[h] += a[h] * b[h]
    # Sigma -= G^T G on the lower triangle, three rows of G per pass.
    for c3 in range(0, n_rows, 3):
        for i in range(d):
            a0, a1, a2 = G[c3, i], G[c3 + 1, i], G[c3 + 2, i]
            base = i * (i + 1) // 2
            for j in range(i + 1):
                out = cov[base + j]
                b0, b1, b2 = G[c3, j], G[c3 + 1, j], G[c3 + 2, j]
                for h in range(n):
                    out[h] -= a0[h] * b0[h] + a1[h] * b1[h] + a2[h] * b2[h]


@numba.njit(cache=True, boundscheck=False)
def compact_columns(a, src):
    """In place: column k of the 2-D ``a`` becomes column src[k] (src increasing)."""
    for row in a:
        for k in range(src.shape[0]):
            row[k] = row[src[k]]


@numba.njit(cache=True, fastmath=False, boundscheck=False)
def mean_trajectory(W, z, centers, width, alpha):
    """Mean positions, velocities, accelerations (len(z), n) of the DOFs with weights W (n, N)
    at phases z for the phase speed alpha: eqs. 1-3 with GaussianBasis.evaluate's basis and its
    clamping (psi held, derivatives zero outside [0, 1]), in one pass without temporaries."""
    T, N, n = z.shape[0], centers.shape[0], W.shape[0]
    pos = np.zeros((T, n))
    vel = np.zeros((T, n))
    acc = np.zeros((T, n))
    h = width * width
    b = np.empty(N)
    db = np.empty(N)
    ddb = np.empty(N)
    for t in range(T):
        inside = 0.0 <= z[t] <= 1.0
        zc = min(max(z[t], 0.0), 1.0)
        s = ds = dds = 0.0
        for i in range(N):
            d = zc - centers[i]
            b[i] = np.exp(-0.5 * d * d / h)
            db[i] = -b[i] * d / h
            ddb[i] = b[i] * (d * d / (h * h) - 1.0 / h)
            s += b[i]
            ds += db[i]
            dds += ddb[i]
        for i in range(N):
            psi = b[i] / s
            for j in range(n):
                pos[t, j] += psi * W[j, i]
            if inside:
                dpsi = (db[i] - psi * ds) / s
                ddpsi = (ddb[i] - 2.0 * dpsi * ds - psi * dds) / s
                for j in range(n):
                    vel[t, j] += alpha * dpsi * W[j, i]
                    acc[t, j] += alpha * alpha * ddpsi * W[j, i]
    return pos, vel, acc
