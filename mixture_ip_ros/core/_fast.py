"""The core layer's fast paths: compiled (numba) and numpy code that replaces a plain
computation of the layer where the online estimator spends its time. Each says which plain
function it must equal, and the tests compare them (test_core_fast, test_core_online):

- kalman_update: observations in turn, every hypothesis; the recursive form of
  promp.weight_posterior (the batch conditioning, eqs. 3-5 and 17-18), equal to rounding;
- basis_rows: GaussianBasis.__call__ (psi clamped to [0, 1]), equal to rounding;
- expected_trajectory: the means of interaction.trajectory_distribution (mean_trajectory), and
  their expectation over phase speeds, equal to rounding.

Kalman update. Per hypothesis h the observed-agent weights have N(mu_h, Sigma_h); the
observation y = (I_P kron psi_h^T) w + e, e ~ N(0, diag(noise)). The update factors
S = L L^T (P x P) and applies G = L^-1 H Sigma, Sigma -= G^T G, which keeps Sigma positive
definite over thousands of updates (the textbook K H Sigma form drifts). Cost O(P d^2) per
hypothesis.

Layout: hypotheses (columns) in groups of LANES = 8, each group contiguous, so one SIMD
register holds one entry of eight hypotheses and a group's state (d (d + 1) / 2 LANES
doubles) is streamed once per pass. Sigma is stored as its lower triangle only (symmetric by
construction, half the update): entry (i, j), j <= i, of column c = g LANES + l is
cov[g, (i (i + 1) / 2 + j) LANES + l]; mu[g, i LANES + l] is entry i of its mean. The columns
of the groups past the tracked ones, and the lanes past them in the last group, hold valid states
that are updated with the others and never read (see OnlineEstimator's pruning).

Every kernel of the layer that calls another or uses the lane type is in this one file:
numba's cache of a kernel is invalidated by edits to the kernel's own file only, so kernels
that call one another (and the lane type they share) must change together. The change
points' kernels, which call only each other, are in _fast_switching.
"""

import operator

import numba
import numpy as np
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic, models, overload, register_model

_LOG_2PI = float(np.log(2.0 * np.pi))


# ------------------------------------------------------------------ SIMD lanes
# Eight float64 lanes as one value in compiled code (an LLVM <8 x double>). numba vectorises
# only innermost loops, and only where it can check that the arrays a loop writes do not
# overlap those it reads, so a loop that keeps partial sums in registers across rows, or
# writes two outputs, stays scalar; with an explicit lane type the kernel holds eight
# hypotheses' values in one register and reuses it. LLVM lowers the type to what the CPU has
# (one AVX-512 register, two AVX2 ones, four SSE2/NEON ones). In compiled code only:
# vload(a, i) / vstore(a, i, v) read / write a[i:i + LANES] of a 1-D C-contiguous float64 array
# without bounds checks (the caller keeps i + LANES <= len(a)); vsplat(x) has x in every lane;
# +, -, *, / are lane-wise and may fuse a multiply-add (as fastmath={'contract'}); vsqrt is the
# lane-wise square root.

LANES = 8
_LANE_VECTOR = ir.VectorType(ir.DoubleType(), LANES)
_CONTRACT = ('contract',)


class _VecType(types.Type):
    def __init__(self):
        super().__init__(name=f'f64x{LANES}')


vec = _VecType()


@register_model(_VecType)
class _VecModel(models.PrimitiveModel):
    def __init__(self, dmm, fe_type):
        super().__init__(dmm, fe_type, _LANE_VECTOR)


def _is_row(a):
    return isinstance(a, types.Array) and a.dtype == types.float64 and a.ndim == 1 \
        and a.layout == 'C'


def _lanes_pointer(context, builder, aryty, ary, i):
    data = context.make_array(aryty)(context, builder, ary).data
    return builder.bitcast(builder.gep(data, [i]), _LANE_VECTOR.as_pointer())


@intrinsic
def vload(typingctx, a, i):
    if not (_is_row(a) and isinstance(i, types.Integer)):
        return None

    def codegen(context, builder, sig, args):
        return builder.load(_lanes_pointer(context, builder, sig.args[0], args[0], args[1]),
                            align=8)
    return vec(a, i), codegen


@intrinsic
def vstore(typingctx, a, i, v):
    if not (_is_row(a) and isinstance(i, types.Integer) and v == vec):
        return None

    def codegen(context, builder, sig, args):
        builder.store(args[2], _lanes_pointer(context, builder, sig.args[0], args[0], args[1]),
                      align=8)
        return context.get_dummy_value()
    return types.none(a, i, v), codegen


@intrinsic
def vsplat(typingctx, x):
    if not isinstance(x, types.Float):
        return None

    def codegen(context, builder, sig, args):
        x = context.cast(builder, args[0], sig.args[0], types.float64)
        one = builder.insert_element(ir.Constant(_LANE_VECTOR, ir.Undefined), x,
                                     ir.Constant(ir.IntType(32), 0))
        return builder.shuffle_vector(one, one, ir.Constant(ir.VectorType(ir.IntType(32), LANES),
                                                             [0] * LANES))
    return vec(x), codegen


@intrinsic
def vsqrt(typingctx, v):
    if v != vec:
        return None

    def codegen(context, builder, sig, args):
        fn = cgutils.get_or_insert_function(builder.module,
                                            ir.FunctionType(_LANE_VECTOR, [_LANE_VECTOR]),
                                            f'llvm.sqrt.v{LANES}f64')
        return builder.call(fn, [args[0]])
    return vec(v), codegen


def _lanewise(name):
    @intrinsic
    def op(typingctx, a, b):
        if not (a == vec and b == vec):
            return None

        def codegen(context, builder, sig, args):
            return getattr(builder, name)(args[0], args[1], flags=_CONTRACT)
        return vec(a, b), codegen

    def impl(a, b):
        if a == vec and b == vec:
            return lambda a, b: op(a, b)
    return impl


for _op, _name in ((operator.add, 'fadd'), (operator.sub, 'fsub'), (operator.mul, 'fmul'),
                   (operator.truediv, 'fdiv')):
    overload(_op)(_lanewise(_name))


@numba.njit(cache=True, nogil=True, fastmath=False, boundscheck=False)
def _basis_row(z, centers, width, out):
    """psi(z) of GaussianBasis (clamped to [0, 1]) into ``out`` (N,)."""
    N = centers.shape[0]
    inv = 0.5 / (width * width)
    zc = min(max(z, 0.0), 1.0)
    s = 0.0
    for n in range(N):
        e = zc - centers[n]
        out[n] = np.exp(-e * e * inv)
        s += out[n]
    for n in range(N):
        out[n] /= s


@numba.njit(cache=True, nogil=True, fastmath=False, boundscheck=False)
def basis_rows(z, centers, width):
    """psi(z) of GaussianBasis (clamped to [0, 1]) for each phase in z: (M, N)."""
    out = np.empty((z.shape[0], centers.shape[0]))
    for m in range(z.shape[0]):
        _basis_row(z[m], centers, width, out[m])
    return out


def lane_array(shape):
    """An empty float64 array (groups, m LANES) whose rows start on a boundary of LANES doubles
    (64 bytes, a cache line): an unaligned vload / vstore reads two cache lines, and the state
    of kalman_update is read and written that way throughout (numpy aligns to 16 bytes)."""
    size = int(np.prod(shape))
    buffer = np.empty(size + LANES)
    start = (-buffer.ctypes.data % (LANES * 8)) // 8
    return buffer[start:start + size].reshape(shape)


def to_lanes(columns):
    """Per-column rows (C, m), C a multiple of LANES, to kalman_update's lane groups
    (C / LANES, m LANES), in a :func:`lane_array`."""
    C, m = columns.shape
    out = lane_array((C // LANES, m * LANES))
    out.reshape(C // LANES, m, LANES)[...] = columns.reshape(C // LANES, LANES, m
                                                              ).transpose(0, 2, 1)
    return out


def from_lanes(groups):
    """Inverse of to_lanes (a copy)."""
    G, mW = groups.shape
    return groups.reshape(G, mW // LANES, LANES).transpose(0, 2, 1).reshape(G * LANES, mW // LANES)


def tri_index(d):
    """(d, d) positions of Sigma[i, j] in the packed lower triangle (both halves)."""
    i, j = np.indices((d, d))
    hi, lo = np.maximum(i, j), np.minimum(i, j)
    return hi * (hi + 1) // 2 + lo


@numba.njit(cache=True, inline='always')
def _tri(i, j):
    return i * (i + 1) // 2 + j if j <= i else j * (j + 1) // 2 + i


# 'contract' only: multiply-adds fused, no reassociation; every lane computed alike.
@numba.njit(cache=True, nogil=True, fastmath={'contract'}, boundscheck=False)
def kalman_update(cov, mu, loglik, n, alpha_index, alphas, phase0, times, centers, width, ys,
                  noise, log_prior, hypothesis, joint, trace):
    """The observations ``ys`` (J, P) at ``times`` (J,) s, in that order, in place for the first
    ``n`` columns (the tracked hypotheses; the rest of their last group is updated too): for
    each, Sigma and mu conditioned on y (eq. 4 in Kalman form) and loglik += log N(y; H mu,
    H Sigma H^T + R) (the factor of eq. 18); then the posterior (eq. 16) into ``joint``.
    ``trace`` (J, columns) gets the loglik of the groups updated after each observation (what a
    caller needs to read between them, e.g. log p(D)); its other columns are not written.
    Returns the smallest posterior probability of a tracked hypothesis.

    Each group of LANES columns takes every observation before the next group starts: a
    group's state (d (d + 1) / 2 LANES doubles, 66 kB at d = 45) stays in the core's cache for
    all of them, where one observation at a time streams every group's state through memory
    once per observation (1.2 MB at 150 hypotheses, more than a core's L2). Each column's
    arithmetic and its order are those of J calls with one observation each, so the result is
    the same to the bit; only the posterior in between is not computed (pruning needs it after
    each one).

    cov (groups, d (d + 1) / 2 LANES), mu (groups, d LANES) (see the module's layout); per
    column c: loglik[c], phase speed alphas[alpha_index[c]] and phase phase0[alpha_index[c]]
    at t = 0 (H = I_P kron psi(phase0 + alpha t)^T, eq. 15 with ``centers``, ``width``; phase0
    is 0 but where a change of mind started a pattern mid-way, core.switching), log_prior[c],
    and which hypothesis it is, hypothesis[c];
    noise (groups, P LANES) = diag R of each column, in the lane layout (tied across
    components or not).
    joint (K M,): p(k, alpha_m | D) renormalised over the tracked hypotheses, 0 for the others;
    empty (0,): not computed, and 0.0 returned (a caller with a posterior of its own: the change
    points' belief, core.switching, and their segments' filters, which have none).
    """
    d = mu.shape[1] // LANES
    J, P = ys.shape
    N = centers.shape[0]
    # Basis rows once per (observation, phase speed in use), the lanes past the n-th column
    # in the last group included: they are updated with the others and must stay valid.
    used = np.zeros(alphas.shape[0], dtype=np.bool_)
    for c in range(-(-n // LANES) * LANES):
        used[alpha_index[c]] = True
    psi = np.empty((J, alphas.shape[0], N))
    for j in range(J):
        for a in range(alphas.shape[0]):
            if used[a]:
                _basis_row(phase0[a] + alphas[a] * times[j], centers, width, psi[j, a])
    phi = np.empty(N * LANES)
    n_rows = -(-P // 3) * 3                    # G in groups of three rows (extra rows zero)
    G = np.zeros(n_rows * d * LANES)
    L = np.empty(P * P * LANES)
    r = np.empty(P * LANES)
    for g in range(-(-n // LANES)):
        cov_g = cov[g]
        mu_g = mu[g]
        noise_g = noise[g]
        for obs in range(J):
            y = ys[obs]
            _absorb_one(cov_g, mu_g, noise_g, loglik, g, alpha_index, psi[obs], y, phi, G, L,
                        r, d, P, N, n_rows)
            for lane in range(LANES):
                trace[obs, g * LANES + lane] = loglik[g * LANES + lane]
    if joint.shape[0] == 0:
        return 0.0
    # Posterior over the tracked hypotheses (eq. 16 with the mixture weight in the prior).
    top = -np.inf
    for c in range(n):
        top = max(top, log_prior[c] + loglik[c])
    joint[:] = 0.0
    total = 0.0
    for c in range(n):
        e = np.exp(log_prior[c] + loglik[c] - top)
        joint[hypothesis[c]] = e
        total += e
    smallest = 1.0
    for c in range(n):
        joint[hypothesis[c]] /= total
        smallest = min(smallest, joint[hypothesis[c]])
    return smallest


@numba.njit(cache=True, nogil=True, fastmath={'contract'}, boundscheck=False, inline='always')
def _absorb_one(cov_g, mu_g, noise_g, loglik, g, alpha_index, psi, y, phi, G, L, r, d, P, N,
                n_rows):
    """One observation ``y`` for the LANES columns of group g (kalman_update's body): ``psi``
    (M, N) holds the basis row at its time of each phase speed in use."""
    for lane in range(LANES):
        a = alpha_index[g * LANES + lane]
        for k in range(N):
            phi[k * LANES + lane] = psi[a, k]
    # H Sigma: G[p, j] = sum_k psi_k Sigma[pN + k, j], four columns j per pass.
    for p in range(P):
        j = 0
        while j < d:
            if j + 4 <= d:
                a0 = a1 = a2 = a3 = vsplat(0.0)
                for k in range(N):
                    i = p * N + k
                    f = vload(phi, k * LANES)
                    a0 = a0 + f * vload(cov_g, _tri(i, j) * LANES)
                    a1 = a1 + f * vload(cov_g, _tri(i, j + 1) * LANES)
                    a2 = a2 + f * vload(cov_g, _tri(i, j + 2) * LANES)
                    a3 = a3 + f * vload(cov_g, _tri(i, j + 3) * LANES)
                o = (p * d + j) * LANES
                vstore(G, o, a0)
                vstore(G, o + LANES, a1)
                vstore(G, o + 2 * LANES, a2)
                vstore(G, o + 3 * LANES, a3)
                j += 4
            else:
                a0 = vsplat(0.0)
                for k in range(N):
                    a0 = a0 + vload(phi, k * LANES) * vload(cov_g, _tri(p * N + k, j) * LANES)
                vstore(G, (p * d + j) * LANES, a0)
                j += 1
    # S = H Sigma H^T + R (lower half) and the residual y - H mu.
    for p in range(P):
        for q in range(p + 1):
            a0 = vload(noise_g, p * LANES) if q == p else vsplat(0.0)
            for k in range(N):
                a0 = a0 + vload(G, (p * d + q * N + k) * LANES) * vload(phi, k * LANES)
            vstore(L, (p * P + q) * LANES, a0)
        a0 = vsplat(y[p])
        for k in range(N):
            a0 = a0 - vload(phi, k * LANES) * vload(mu_g, (p * N + k) * LANES)
        vstore(r, p * LANES, a0)
    # S = L L^T in place.
    for i in range(P):
        for j in range(i + 1):
            a0 = vload(L, (i * P + j) * LANES)
            for q in range(j):
                a0 = a0 - vload(L, (i * P + q) * LANES) * vload(L, (j * P + q) * LANES)
            if i == j:
                a0 = vsqrt(a0)
            else:
                a0 = a0 / vload(L, (j * P + j) * LANES)
            vstore(L, (i * P + j) * LANES, a0)
    # G = L^-1 H Sigma and r = L^-1 (y - H mu) in place.
    for p in range(P):
        inv = vsplat(1.0) / vload(L, (p * P + p) * LANES)
        for j in range(d):
            a0 = vload(G, (p * d + j) * LANES)
            for q in range(p):
                a0 = a0 - vload(L, (p * P + q) * LANES) * vload(G, (q * d + j) * LANES)
            vstore(G, (p * d + j) * LANES, a0 * inv)
        a0 = vload(r, p * LANES)
        for q in range(p):
            a0 = a0 - vload(L, (p * P + q) * LANES) * vload(r, q * LANES)
        vstore(r, p * LANES, a0 * inv)
    # log N(y; H mu, S) = -(P log 2 pi + log det S + |r|^2) / 2, det S = prod L_pp^2.
    for lane in range(LANES):
        logdet, quad, prod = 0.0, 0.0, 1.0
        for p in range(P):
            prod *= L[(p * P + p) * LANES + lane]
            if p % 8 == 7 or p == P - 1:   # L_pp^2 >= min(noise): 8 factors cannot underflow
                logdet += 2.0 * np.log(prod)
                prod = 1.0
            quad += r[p * LANES + lane] ** 2
        loglik[g * LANES + lane] += -0.5 * (P * _LOG_2PI + logdet + quad)
    # mu += G^T r
    for i in range(d):
        a0 = vload(mu_g, i * LANES)
        for p in range(P):
            a0 = a0 + vload(G, (p * d + i) * LANES) * vload(r, p * LANES)
        vstore(mu_g, i * LANES, a0)
    # Sigma -= G^T G on the lower triangle: three rows of G, rows i and i + 1 of Sigma per
    # pass (they share the loads of G[:, j]).
    for c in range(0, n_rows, 3):
        g0, g1, g2 = c * d * LANES, (c + 1) * d * LANES, (c + 2) * d * LANES
        i = 0
        while i < d:
            a0 = vload(G, g0 + i * LANES)
            a1 = vload(G, g1 + i * LANES)
            a2 = vload(G, g2 + i * LANES)
            base = i * (i + 1) // 2
            if i + 1 < d:
                e0 = vload(G, g0 + (i + 1) * LANES)
                e1 = vload(G, g1 + (i + 1) * LANES)
                e2 = vload(G, g2 + (i + 1) * LANES)
                for j in range(i + 1):
                    b0 = vload(G, g0 + j * LANES)
                    b1 = vload(G, g1 + j * LANES)
                    b2 = vload(G, g2 + j * LANES)
                    o = (base + j) * LANES
                    vstore(cov_g, o, vload(cov_g, o) - (a0 * b0 + a1 * b1 + a2 * b2))
                    o += (i + 1) * LANES                     # entry (i + 1, j)
                    vstore(cov_g, o, vload(cov_g, o) - (e0 * b0 + e1 * b1 + e2 * b2))
                o = (base + 2 * i + 2) * LANES              # entry (i + 1, i + 1)
                vstore(cov_g, o, vload(cov_g, o) - (e0 * e0 + e1 * e1 + e2 * e2))
                i += 2
            else:
                for j in range(i + 1):
                    b0 = vload(G, g0 + j * LANES)
                    b1 = vload(G, g1 + j * LANES)
                    b2 = vload(G, g2 + j * LANES)
                    o = (base + j) * LANES
                    vstore(cov_g, o, vload(cov_g, o) - (a0 * b0 + a1 * b1 + a2 * b2))
                i += 1


@numba.njit(cache=True, nogil=True, boundscheck=False)
def compact_lanes(a, src):
    """In place: column k of the lane-grouped ``a`` (groups, m LANES) becomes column src[k]
    (src increasing, so no column is overwritten before it is moved)."""
    m = a.shape[1] // LANES
    for k in range(src.shape[0]):
        s = src[k]
        if s != k:
            for e in range(m):
                a[k // LANES, e * LANES + k % LANES] = a[s // LANES, e * LANES + s % LANES]


@numba.njit(cache=True, nogil=True, fastmath=False, boundscheck=False)
def expected_trajectory(weights, scales, rates, probs, times, centers, width, derivatives):
    """sum_m probs[m] (the mean positions, velocities, accelerations (len(times), n) of the
    DOFs with weights[m] (n, N) at the phases z = scales[m] times, moving at dz/dt = rates[m]):
    eqs. 1-3 with GaussianBasis.evaluate's basis and its clamping (psi held, derivatives zero
    outside [0, 1]), each path added in the order of m, in one pass without temporaries. The
    expectation over phase-speed hypotheses alpha_m (scales = rates = alphas, times in s), or
    one path at given phases (:func:`mean_trajectory`). Without ``derivatives`` the velocities
    and accelerations (then (0, n)) are not computed: the basis's derivatives are two thirds
    of the work."""
    M, n, N = weights.shape
    T = times.shape[0]
    Td = T if derivatives else 0
    pos = np.zeros((T, n))
    vel = np.zeros((Td, n))
    acc = np.zeros((Td, n))
    h = width * width
    b = np.empty(N)
    db = np.empty(N)
    ddb = np.empty(N)
    row = np.empty((3, n))
    for m in range(M):
        scale, rate, p = scales[m], rates[m], probs[m]
        for t in range(T):
            z = scale * times[t]
            inside = 0.0 <= z <= 1.0
            zc = min(max(z, 0.0), 1.0)
            s = ds = dds = 0.0
            for i in range(N):
                d = zc - centers[i]
                b[i] = np.exp(-0.5 * d * d / h)
                s += b[i]
                if derivatives:
                    db[i] = -b[i] * d / h
                    ddb[i] = b[i] * (d * d / (h * h) - 1.0 / h)
                    ds += db[i]
                    dds += ddb[i]
            row[:] = 0.0
            for i in range(N):
                psi = b[i] / s
                for j in range(n):
                    row[0, j] += psi * weights[m, j, i]
                if derivatives and inside:
                    dpsi = (db[i] - psi * ds) / s
                    ddpsi = (ddb[i] - 2.0 * dpsi * ds - psi * dds) / s
                    for j in range(n):
                        row[1, j] += rate * dpsi * weights[m, j, i]
                        row[2, j] += rate * rate * ddpsi * weights[m, j, i]
            for j in range(n):
                pos[t, j] += p * row[0, j]
                if derivatives:
                    vel[t, j] += p * row[1, j]
                    acc[t, j] += p * row[2, j]
    return pos, vel, acc


_ONE = np.ones(1)


def mean_trajectory(weights, z, centers, width, alpha):
    """Mean positions, velocities, accelerations (len(z), n) of the DOFs with ``weights`` (n, N)
    at phases z for the phase speed alpha: :func:`expected_trajectory` of the one path (scale
    1, probability 1: the same numbers)."""
    return expected_trajectory(np.ascontiguousarray(weights)[None], _ONE,
                               np.array([float(alpha)]), _ONE, np.asarray(z, dtype=float),
                               centers, width, True)
