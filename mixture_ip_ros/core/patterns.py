"""Pattern discovery: which demonstrations show the same interaction, and how many there are.

ProMP weights are not paths. The basis functions overlap, so a weight vector can move a long
way in directions that barely change its path (eq. 14 with overlapping Gaussians is ill-
conditioned), and on real recordings those directions vary far more within an interaction than
the directions that tell interactions apart. Demonstrations are therefore compared by their
paths, aligned in time (core.pattern_space.PatternSpace: a few coordinates per demonstration
whatever pace each person kept).

A dozen demonstrations per pattern cannot estimate a covariance of 45-150 weights, and a mixture
fitted there puts every demonstration in a cluster of its own or all in one. Patterns are found
in those few coordinates instead. There a
mixture of t distributions (:class:`PatternMixture`; heavy tails, for the atypical recordings
real people make) has full scale matrices shrunk towards the one pooled within its components
(``prior_strength`` pseudo-demonstrations, as the weight model's prior), so a component with
few members borrows the shape the others share. The number of
patterns is where the leave-one-out log-likelihood of held-out demonstrations in that space
stops rising (:func:`heldout_curve`, read by ``mixture.selection_curve``). Where a pair
stands can be left out of a pattern (:func:`translation_for`, :func:`without_offsets`).

The full Mixture of Interaction ProMPs (core.mixture) starts its EM from these clusters.
"""

import operator
from typing import NamedTuple

import numpy as np
from scipy.special import gammaln

from .basis import GaussianBasis
from .kmeans import kmeans_runs
from .numerics import logsumexp_rows, tie_tolerance
from .promp import LOG_2PI

# Share of the spread between demonstrations the pattern space keeps.
VARIANCE_KEPT = 0.9
# Degrees of freedom of the pattern mixture's t components (PatternMixture: why t, why 4).
TAIL_DOF = 4.0


def translation_groups(groups, n_dofs: int) -> tuple:
    """``groups`` checked: DOF indices (into the stacked [observed, controlled] DOFs) that move
    together when the interaction happens elsewhere, one tuple per axis (e.g. ((0, 3), (1, 4),
    (2, 5)): both hands' x, y and z); () for none."""
    out = tuple(tuple(operator.index(j) for j in g) for g in (() if groups is None else groups))
    flat = [j for g in out for j in g]
    if any(not g for g in out) or len(set(flat)) != len(flat) or not all(
            0 <= j < n_dofs for j in flat):
        raise ValueError(f'translation groups must be disjoint, non-empty groups of DOF indices '
                         f'in 0..{n_dofs - 1}, got {groups!r}')
    return out


TRANSLATION_MODES = ('none', 'shared', 'observed')


def translation_for(mode: str, n_observed: int, n_controlled: int) -> tuple:
    """The translation groups of a named ``mode`` (:data:`TRANSLATION_MODES`):

    - 'none': where a demonstration happened is part of it (one frame for every recording,
      e.g. a wrist in a fixed robot's base frame);
    - 'shared': both agents are positions in one frame, observed DOF i and controlled DOF i
      the same axis, and where the pair stood is not part of the interaction (recordings of
      several sessions, a tracker's frame that moved): groups (i, P + i);
    - 'observed': a single agent's positions, where its movement happened not part of it:
      groups (i,). With a controlled agent it is refused: where a person stands moves a robot's
      joints in ways a common shift does not describe; name the DOFs that move together.
    """
    if mode not in TRANSLATION_MODES:
        raise ValueError(f'translation must be one of {TRANSLATION_MODES}, got {mode!r}')
    if mode == 'none':
        return ()
    if mode == 'shared':
        if n_observed != n_controlled:
            raise ValueError(f"translation 'shared' pairs observed DOF i with controlled DOF i: "
                             f'it needs as many of each, got {n_observed} and {n_controlled}')
        return tuple((i, n_observed + i) for i in range(n_observed))
    if n_controlled:
        raise ValueError("translation 'observed' is for a single agent; with a controlled agent "
                         "use 'shared' (both agents' positions in one frame) or name the groups")
    return tuple((i,) for i in range(n_observed))


def offset_operators(n_basis: int, n_dofs: int, groups):
    """(T (g, D N), B (D N, g)) of the translation ``groups`` (:func:`translation_groups`) in
    stacked weights of D DOFs: o = T w is each group's offset, the mean over its DOFs of each
    path's mean position over the phase (the path metric's least-squares common shift, a
    whole-movement average, not one sample); w + B o moves every DOF of group a by o_a (the
    basis is normalised, so a constant path c has weights c 1). T B = I, so w - B T w has
    offset zero and is unchanged by any common shift of a group's DOFs."""
    groups = translation_groups(groups, n_dofs)
    T = np.zeros((len(groups), n_dofs * n_basis))
    B = np.zeros((n_dofs * n_basis, len(groups)))
    mean_position = GaussianBasis(n_basis).gram().sum(axis=1)    # integral of psi over z
    for a, g in enumerate(groups):
        for j in g:
            T[a, j * n_basis:(j + 1) * n_basis] = mean_position / len(g)
            B[j * n_basis:(j + 1) * n_basis, a] = 1.0
    return T, B


def without_offsets(W, n_basis: int, groups) -> np.ndarray:
    """Stacked weights W (n, D N) with each translation group's offset removed (w - B T w,
    :func:`offset_operators`): what is left of a demonstration wherever it happened."""
    W = np.asarray(W, dtype=float)
    if not translation_groups(groups, W.shape[1] // n_basis):
        return W
    T, B = offset_operators(n_basis, W.shape[1] // n_basis, groups)
    return W - (W @ T.T) @ B.T


def _log_densities(X, means, chols, dof: float):
    """(log f(x_i; mu_k, Sigma_k), the squared Mahalanobis distances), each (B, n, K), of B
    batches of points X (B, n, q) under K components each (means (B, K, q), lower Cholesky
    factors of the scale matrices (B, K, q, q)); f the multivariate t density of ``dof``
    degrees of freedom (normal where dof is inf)."""
    q = X.shape[2]
    E = X[:, None] - means[:, :, None]                          # (B, K, n, q)
    # One batched LAPACK call for every component of every batch: the cluster-stability fits
    # make thousands of EM iterations on a few hundred numbers, where a call per component
    # costs more than its arithmetic.
    sol = np.linalg.solve(chols, E.swapaxes(-1, -2))            # L^-1 (x - mu), (B, K, q, n)
    dist = np.einsum('bkqn,bkqn->bnk', sol, sol)
    log_det = 2 * np.log(np.diagonal(chols, axis1=-2, axis2=-1)).sum(axis=-1)[:, None, :]
    if np.isinf(dof):
        return -0.5 * (q * LOG_2PI + log_det + dist), dist
    return (gammaln(0.5 * (dof + q)) - gammaln(0.5 * dof) - 0.5 * q * np.log(dof * np.pi)
            - 0.5 * log_det - 0.5 * (dof + q) * np.log1p(dist / dof)), dist


def _logsumexp_last(a):
    """log sum exp over the last axis of a (B, n, K) array: (B, n)."""
    return logsumexp_rows(a.reshape(-1, a.shape[-1])).reshape(a.shape[:-1])


class PatternMixture:
    """A mixture of multivariate t distributions in the pattern space (Peel and McLachlan
    2000), ``dof`` degrees of freedom (``np.inf``: a Gaussian mixture), its scale matrices
    shrunk towards the one pooled within the components: Sigma_k = (S_k + s S_pooled) /
    (n_k + s), S_k the scatter of component k weighted by the responsibilities r_ik and the
    t's weights u_ik = (dof + q) / (dof + d_ik) (d_ik the squared Mahalanobis distance),
    S_pooled = sum_k S_k / n and s = ``prior_strength`` pseudo-demonstrations (regularised
    discriminant analysis, Friedman 1989: with s = 0 every component has its own scale, as s
    grows they share one). A floor of ``floor`` times each coordinate's variance keeps them
    positive definite.

    Why t rather than normal: real recordings hold a few atypical performances (a slow
    fist-bump, a wave cut short, a tracker that jumped) far in a normal component's tails,
    where one recording's density swings by several nats with any change of the pooled shape,
    as when another pattern is split off; a few such recordings then decide a comparison of K
    that the typical ones settle the other way (NuiSI v2, K = 4 against 3 held out in the two
    folds that chose 3: a median gain of 0.59 and 0.39 nats per recording, a mean of 0.13 and
    0.03, pulled down by two or three recordings at -2 to -4). A t component down-weights them
    in the fit and bounds their cost in the score. dof = 4 is Lange, Little and Taylor's (1989)
    choice for robust estimation, not a value fitted to any data here.

    EM (ECM: responsibilities and weights u from the current parameters, then the mixture
    weights, means and scales) from k-means++ starts (core.kmeans), ``n_init`` of them, the
    one with the highest log-likelihood kept among those whose every component is the most
    probable one for at least ``min_members`` demonstrations (any, if none is); or from given
    responsibilities (``fit(X, resp=...)``). A component of one demonstration is the mixture's
    classic spurious maximum (McLachlan and Peel 2000, sec. 3.10): one atypical demonstration
    sits at its own mean with a scale that is all prior, and the likelihood it gains there
    outweighs keeping two real patterns apart (NuiSI v2: one slow rocket fist-bump alone,
    handshake and parachute fist-bump merged, in 3 of 5 folds). A pattern is something shown
    at least twice. EM stops when the log-likelihood gains less than ``tol`` relative or after
    ``max_iter`` iterations: 1e-6 of a pattern-space log-likelihood of a few hundred nats is
    1e-4 nats, two orders below the 0.01 nats per demonstration the K criterion resolves
    (the t's ECM creeps linearly, and a tighter tolerance only adds iterations: 1e-9 takes
    1.5 times as long on NuiSI v2 for curves equal to 0.001 nats). Fitted: ``weights_`` (K,),
    ``means_`` (K, q), ``covariances_`` (K, q, q; the scale matrices, a t's covariance being
    dof / (dof - 2) times its scale),
    ``resp_`` (n, K), ``log_likelihood_`` (of the training data, under the fitted model),
    ``n_iter_``.

    :meth:`fit_many` fits one mixture of this configuration to each of several data sets of
    the same shape (the subsamples of cluster stability, the leave-one-out sets) with every EM
    run of every set side by side, each stopping on its own: the same fits as one ``fit``
    each, in a fraction of the time (the runs are a few hundred numbers each, where numpy's
    per-call cost is the price).
    """

    def __init__(self, n_components: int, prior_strength: float = 10.0, floor: float = 1e-6,
                 n_init: int = 10, random_state=0, max_iter: int = 200, tol: float = 1e-6,
                 min_members: int = 2, dof: float = TAIL_DOF):
        self.n_components = n_components
        self.dof = dof
        self.prior_strength = prior_strength
        self.min_members = min_members
        self.floor = floor
        self.n_init = n_init
        self.random_state = random_state
        self.max_iter = max_iter
        self.tol = tol

    def _params(self) -> dict:
        return {name: getattr(self, name) for name in
                ('n_components', 'prior_strength', 'floor', 'n_init', 'random_state',
                 'max_iter', 'tol', 'min_members', 'dof')}

    def fit(self, X, resp=None, fixed=None) -> 'PatternMixture':
        """``fixed`` (n,) bool, with ``resp``: the rows whose responsibilities stay as they
        start (named demonstrations: semi-supervised EM, whose log-likelihood is the
        complete-data one for those rows, the marginal one for the others)."""
        fitted = self.fit_many(np.asarray(X, dtype=float)[None],
                               None if resp is None else [resp], fixed)[0]
        self.__dict__.update(fitted.__dict__)
        return self

    def fit_many(self, Xs, resps=None, fixed=None) -> list:
        """One fitted copy of this mixture for each data set in ``Xs`` ((m, n, q) or a list of
        m (n, q) arrays), each as ``fit(Xs[j], resps[j], fixed)`` would fit it."""
        Xs = np.asarray(Xs, dtype=float)
        if Xs.ndim != 3 or not np.all(np.isfinite(Xs)):
            raise ValueError(f'X must be a finite (n, q) array, got shape {Xs.shape[1:]}')
        m, n, q = Xs.shape
        K = int(self.n_components)
        if not 1 <= K <= n:
            raise ValueError(f'n_components must be in 1..{n}, got {self.n_components!r}')
        if int(self.min_members) != self.min_members or self.min_members < 1:
            raise ValueError(f'min_members must be a positive integer, got {self.min_members!r}')
        if not self.dof > 0:
            raise ValueError(f'dof must be positive (inf: normal), got {self.dof!r}')
        if fixed is not None and (resps is None or np.shape(fixed) != (n,)):
            raise ValueError('fixed rows need starting responsibilities and one flag per row')
        floors = self.floor * np.maximum(Xs.var(axis=1), 1e-300)            # (m, q)
        if resps is not None:
            starts = [[np.asarray(r, dtype=float)] for r in resps]
        elif K == 1:
            starts = [[np.ones((n, 1))] for _ in range(m)]
        else:
            seeds = np.random.default_rng(self.random_state).integers(2 ** 31, size=self.n_init)
            starts = [list(np.eye(K)[kmeans_runs(X, K, seeds)]) for X in Xs]
        owner = np.repeat(np.arange(m), [len(s) for s in starts])
        runs = self._ecm(Xs[owner], np.stack([R for s in starts for R in s]), floors[owner],
                         None if fixed is None else np.asarray(fixed, dtype=bool))
        enough = min(int(self.min_members), n // K)
        out = []
        for j in range(m):
            best, best_key = None, None
            for r in np.flatnonzero(owner == j):
                ll, weights, means, covs, R, n_iter = (a[r] for a in runs)
                members = np.bincount(np.argmax(R, axis=1), minlength=K)
                key = (bool(members.min() >= enough), float(ll))
                # A start better by less than a tie (core.numerics) does not replace an
                # earlier one: two starts that reach the same maximum keep the same one on
                # every machine.
                if best is None or key[0] > best_key[0] or (
                        key[0] == best_key[0] and key[1] > best_key[1] + tie_tolerance(key[1])):
                    best, best_key = r, key
            fitted = PatternMixture(**self._params())
            (fitted.log_likelihood_, fitted.weights_, fitted.means_, fitted.covariances_,
             fitted.resp_, fitted.n_iter_) = (a[best] for a in runs)
            fitted.log_likelihood_ = float(fitted.log_likelihood_)
            fitted.n_iter_ = int(fitted.n_iter_)
            fitted._chols = np.linalg.cholesky(fitted.covariances_)
            out.append(fitted)
        return out

    def _m_step(self, X, R, U, floors):
        """Mixture weights, means and shrunk scales of B batches at once: X (B, n, q),
        responsibilities R and t weights U (B, n, K), floors (B, q)."""
        n, q = X.shape[1:]
        tiny = 10 * np.finfo(float).eps
        nk = R.sum(axis=1) + tiny                                           # (B, K)
        RU = R * U
        means = (RU.swapaxes(1, 2) @ X) / (RU.sum(axis=1) + tiny)[..., None]
        E = X[:, None] - means[:, :, None]                                  # (B, K, n, q)
        scatter = (RU.swapaxes(1, 2)[..., None] * E).swapaxes(-1, -2) @ E   # (B, K, q, q)
        pooled = scatter.sum(axis=1, keepdims=True) / n
        s = self.prior_strength
        covs = (scatter + s * pooled) / (nk + s)[..., None, None]
        covs[..., np.arange(q), np.arange(q)] += floors[:, None, :]
        return nk / n, means, 0.5 * (covs + covs.swapaxes(-1, -2))

    def _ecm(self, X, R, floors, fixed=None):
        """ECM from B starts side by side (X (B, n, q), starting responsibilities R (B, n, K),
        floors (B, q)), each run stopping on its own; the rows in ``fixed`` (n,) keep their
        starting responsibilities. Returns the best iteration of each run as arrays over B:
        (log-likelihood, weights, means, scales, the responsibilities those parameters were
        estimated from, iteration)."""
        B, n, q = X.shape
        K = R.shape[2]
        R = R.copy()
        start = None if fixed is None else R.copy()
        # The t's weights u_ik; all 1 for the first M-step (responsibilities alone) and for
        # normal components throughout.
        U = np.ones_like(R)
        best = (np.full(B, -np.inf), np.empty((B, K)), np.empty((B, K, q)),
                np.empty((B, K, q, q)), np.empty_like(R), np.zeros(B, dtype=int))
        prev = np.full(B, -np.inf)
        active = np.arange(B)
        for it in range(1, self.max_iter + 1):
            Ra = R[active]
            weights, means, covs = self._m_step(X[active], Ra, U[active], floors[active])
            log_f, dist = _log_densities(X[active], means, np.linalg.cholesky(covs), self.dof)
            lp = np.log(weights)[:, None, :] + log_f
            norm = _logsumexp_last(lp)
            if fixed is not None:
                norm[:, fixed] = np.sum(start[active][:, fixed] * lp[:, fixed], axis=2)
            ll = norm.sum(axis=1)
            better = (ll > best[0][active]) | (it == 1)
            for stored, value in zip(best, (ll, weights, means, covs, Ra,
                                            np.full(len(active), it))):
                stored[active[better]] = value[better]
            R[active] = np.exp(lp - norm[..., None])
            if fixed is not None:
                R[np.ix_(active, fixed)] = start[np.ix_(active, fixed)]
            if not np.isinf(self.dof):
                U[active] = (self.dof + q) / (self.dof + dist)
            going = ll - prev[active] > self.tol * np.maximum(1.0, np.abs(ll))
            prev[active] = ll
            active = active[going]
            if not active.size:
                break
        return best

    def _joint(self, X):
        X = np.asarray(X, dtype=float)
        return (np.log(self.weights_) + _log_densities(X[None], self.means_[None],
                                                       self._chols[None], self.dof)[0][0])

    def score_samples(self, X) -> np.ndarray:
        """log p(x_i) under the mixture, (n,)."""
        return logsumexp_rows(self._joint(X))

    def predict(self, X) -> np.ndarray:
        return np.argmax(self._joint(X), axis=1)


class HeldOut(NamedTuple):
    """Leave-one-out scores of :func:`heldout_curve`, each (len(candidates), n)."""

    loglik: np.ndarray      # log p_K(x_i) of each held-out demonstration
    robust: np.ndarray      # log((1 - eps) p_K(x_i) + eps p_1(x_i)), eps = 1 / n


def heldout_curve(X, candidates, prior_strength: float = 10.0, n_init: int = 10,
                  random_state=0) -> HeldOut:
    """Leave-one-out log-likelihood of every demonstration (rows of X, pattern-space
    coordinates) under a :class:`PatternMixture` of K components fitted to the others, for
    every K in ``candidates``. Each held-out fit starts from the responsibilities the mixture
    of all demonstrations gives the others (one EM run instead of ``n_init``); the space
    itself is fitted once, without labels, and is the same for every K.

    ``robust``: the same with each held-out demonstration allowed, with probability eps = 1/n,
    to be none of the patterns, scored then by the single Gaussian of the others (K = 1).
    A recording that fits no pattern (a tracker that lost the person, an interaction cut
    half-way) can be far less likely under every pattern than under one broad component
    (hundreds of nats under normal components, tens under the t's); scored plainly, that one
    recording can outweigh the gain of every other and the curve prefer K = 1. With
    eps = 1/n it costs at most log n nats. Higher is better."""
    X = np.asarray(X, dtype=float)
    n = len(X)
    out = np.empty((len(candidates), n))
    single = np.empty(n)
    for a, K in enumerate([1, *candidates]):
        if not 1 <= K <= n - 1:
            raise ValueError(f'leave-one-out of {n} demonstrations cannot fit K = {K}')
        whole = PatternMixture(K, prior_strength, n_init=n_init,
                               random_state=random_state).fit(X)
        scores = single if a == 0 else out[a - 1]
        keep = [np.arange(n) != i for i in range(n)]
        fits = PatternMixture(K, prior_strength).fit_many([X[k] for k in keep],
                                                          [whole.resp_[k] for k in keep])
        scores[:] = [model.score_samples(X[i:i + 1])[0] for i, model in enumerate(fits)]
    eps = 1.0 / n
    return HeldOut(out, np.logaddexp(np.log1p(-eps) + out, np.log(eps) + single))


def adjusted_rand_index(a, b) -> float:
    """Hubert and Arabie's adjusted Rand index of two partitions of the same items (1: the
    same partition, ~0: as alike as chance). Two partitions of one cluster each count as 1."""
    _, a = np.unique(np.asarray(a), return_inverse=True)
    _, b = np.unique(np.asarray(b), return_inverse=True)
    table = np.zeros((a.max() + 1, b.max() + 1))
    np.add.at(table, (a, b), 1)

    def pairs(x):
        return float(np.sum(x * (x - 1)) / 2)
    both, rows, cols = pairs(table), pairs(table.sum(axis=1)), pairs(table.sum(axis=0))
    expected = rows * cols / pairs(np.array([len(a)]))
    top = 0.5 * (rows + cols)
    return 1.0 if top == expected else (both - expected) / (top - expected)


def partition_stability(X, candidates, n_pairs: int = 20, fraction: float = 0.8,
                        prior_strength: float = 10.0, n_init: int = 10,
                        random_state=0) -> np.ndarray:
    """How reproducible each K's partition is (cluster stability: Ben-Hur, Elisseeff and Guyon
    2002; Lange, Roth, Braun and Buhmann 2004): ``n_pairs`` pairs of independent subsamples of
    ``fraction`` of the demonstrations (rows of X), a :class:`PatternMixture` of K components
    fitted to each, both assigning every demonstration; the adjusted Rand index of the two
    assignments. A split the data hold is found again from other demonstrations; a split of
    one pattern in two falls where each subsample's few members put it, and the two
    assignments disagree. The same pairs for every K, so that K can be compared pair by pair.
    K = 1 is one cluster in every subsample: 1. Returns (len(candidates), n_pairs)."""
    X = np.asarray(X, dtype=float)
    n = len(X)
    m = int(round(fraction * n))
    if not 2 <= m <= n:
        raise ValueError(f'subsamples of {fraction!r} of {n} demonstrations are too small')
    rng = np.random.default_rng(random_state)
    draws = [[np.sort(rng.choice(n, m, replace=False)) for _ in range(2)]
             for _ in range(n_pairs)]
    out = np.ones((len(candidates), n_pairs))
    for a, K in enumerate(candidates):
        if not 1 <= K <= m:
            raise ValueError(f'subsamples of {m} demonstrations cannot fit K = {K}')
        if K == 1:
            continue
        fits = PatternMixture(K, prior_strength, n_init=n_init, random_state=random_state
                              ).fit_many([X[idx] for pair in draws for idx in pair])
        for p in range(n_pairs):
            out[a, p] = adjusted_rand_index(fits[2 * p].predict(X), fits[2 * p + 1].predict(X))
    return out
