"""Compiled inner loops of the online estimator: one observation, every hypothesis
(kalman_update), and the mean trajectory that a robot command needs (mean_trajectory).

Per hypothesis h the observed-agent weights have N(mu[h], sigma[h]); the observation
y = (I_P kron psi_h^T) w + e, e ~ N(0, diag(noise)). The update factors S = L L^T (P x P) and
applies G = L^-1 H Sigma, Sigma -= G^T G, which keeps Sigma exactly symmetric and positive
definite over thousands of updates (the textbook K H Sigma form drifts). Cost O(P d^2) per
hypothesis, no allocation in the loop.
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


@numba.njit(cache=True, fastmath=False, boundscheck=False)
def kalman_update(sigma, mu, loglik, psi, psi_index, y, noise):
    """In place: sigma (H, d, d), mu (H, d), loglik (H,) += log N(y; H mu, H Sigma H^T + R).

    ``psi`` (M, N) basis rows per phase hypothesis, ``psi_index`` (H,) which row each
    hypothesis uses.
    """
    n_h, d, _ = sigma.shape
    P = y.shape[0]
    N = psi.shape[1]
    HS = np.empty((P, d))
    n_rows = -(-P // 3) * 3
    G = np.zeros((n_rows, d))
    Sy = np.empty((P, P))
    L = np.zeros((P, P))
    r = np.empty(P)
    for h in range(n_h):
        S = sigma[h]
        phi = psi[psi_index[h]]
        for p in range(P):
            HSp = HS[p]
            for j in range(d):
                HSp[j] = 0.0
            for n in range(N):
                f = phi[n]
                Srow = S[p * N + n]
                for j in range(d):
                    HSp[j] += f * Srow[j]
        for p in range(P):
            for q in range(P):
                acc = 0.0
                for n in range(N):
                    acc += HS[p, q * N + n] * phi[n]
                Sy[p, q] = acc
            Sy[p, p] += noise[p]
            acc = 0.0
            for n in range(N):
                acc += phi[n] * mu[h, p * N + n]
            r[p] = y[p] - acc
        for i in range(P):
            for j in range(i + 1):
                acc = Sy[i, j]
                for q in range(j):
                    acc -= L[i, q] * L[j, q]
                if i == j:
                    L[i, i] = np.sqrt(acc)
                else:
                    L[i, j] = acc / L[j, j]
        logdet = 0.0
        for p in range(P):
            logdet += 2.0 * np.log(L[p, p])
            inv = 1.0 / L[p, p]
            Gp = G[p]
            for j in range(d):
                Gp[j] = HS[p, j]
            for q in range(p):
                lq = L[p, q]
                Gq = G[q]
                for j in range(d):
                    Gp[j] -= lq * Gq[j]
            for j in range(d):
                Gp[j] *= inv
            acc = r[p]
            for q in range(p):
                acc -= L[p, q] * r[q]
            r[p] = acc * inv
        quad = 0.0
        for p in range(P):
            quad += r[p] * r[p]
        loglik[h] += -0.5 * (P * _LOG_2PI + logdet + quad)
        for i in range(d):
            acc = 0.0
            for p in range(P):
                acc += G[p, i] * r[p]
            mu[h, i] += acc
        # Sigma -= G^T G, three rows of G per pass over Sigma (rows past P are zero): one
        # load and store of Sigma per three products, 30 % faster than a pass per row.
        for c in range(0, n_rows, 3):
            Ga, Gb, Gc = G[c], G[c + 1], G[c + 2]
            for i in range(d):
                Si = S[i]
                ga, gb, gc = Ga[i], Gb[i], Gc[i]
                for j in range(d):
                    Si[j] -= ga * Ga[j] + gb * Gb[j] + gc * Gc[j]


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
