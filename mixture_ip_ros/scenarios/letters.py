"""Letters for the phase (thesis 4.3.1) and missing-data (4.3.2) experiments.

2-D letter-"a" trajectories drawn from Gaussian weights of normalized Gaussian basis functions and
a Gaussian phase speed alpha; missing-data training trajectories lose one random block of 180
samples.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from mixture_ip_ros.core.demonstration import Demonstration

# One handwritten "a": the bowl drawn counter-clockwise from its top right, up the stem, down, tail.
LETTER_A = np.array([[1.0, 1.7], [0.6, 2.0], [0.15, 1.75], [0.0, 1.1], [0.25, 0.55], [0.75, 0.6],
                     [1.0, 1.2], [1.02, 1.95], [1.0, 0.9], [1.05, 0.25], [1.35, 0.0]])
LETTER_BASIS = 15
LETTER_DT = 0.01
LETTER_ALPHA = (0.16, 0.04)               # mean, std of the phase speed (1/s)
LETTER_ALPHA_RANGE = (1 / 11.3, 1 / 3.5)  # durations of 3.5-11.3 s: 355-1130 samples at 100 Hz
# Letter units (letter height ~2): the online observation noise of a hand-drawn letter
# (MixtureIProMP's observation_noise), the pen's departure from a smooth ProMP path.
LETTER_OBSERVATION_NOISE = 0.01


class LetterData(NamedTuple):
    """Letter trajectories for the phase (4.3.1) and missing-data (4.3.2) experiments.

    ``train``/``test``: Demonstrations with 2-D ``observed`` (letter units, 1 = letter height / 2)
    and no controlled DOFs; ``train_complete``: the training trajectories before any removal;
    ``train_alpha``/``test_alpha``: the true phase speeds (1/s).
    """

    train: list
    test: list
    train_complete: list
    train_alpha: np.ndarray
    test_alpha: np.ndarray


def _rbf(z, n=LETTER_BASIS):
    centers = np.linspace(0.0, 1.0, n)
    width = 1.0 / (n - 1)
    b = np.exp(-0.5 * ((np.asarray(z)[:, None] - centers) / width) ** 2)
    return b / b.sum(axis=1, keepdims=True)


def letter_prior():
    """Mean (2, B) and covariance (2B, 2B) of the letter weights (x weights then y weights)."""
    from scipy.interpolate import CubicSpline
    chord = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(LETTER_A, axis=0), axis=1))]
    spline = CubicSpline(chord / chord[-1], LETTER_A, bc_type='natural')
    z = np.linspace(0.0, 1.0, 400)
    Phi = _rbf(z)
    W = np.linalg.solve(Phi.T @ Phi + 1e-6 * np.eye(LETTER_BASIS), Phi.T @ spline(z))  # (B, 2)
    mean = W.T
    centroid = mean.mean(axis=1, keepdims=True)
    B = LETTER_BASIS
    modes = [
        ((mean - centroid) * 0.08).ravel(),                        # size
        (np.vstack([mean[1] - centroid[1], np.zeros(B)]) * 0.12).ravel(),  # slant
        (np.vstack([np.ones(B), np.zeros(B)]) * 0.1).ravel(),      # position
        (np.vstack([np.zeros(B), np.ones(B)]) * 0.1).ravel(),
        (np.vstack([np.zeros(B), mean[1] - centroid[1]]) * 0.06).ravel(),  # height only
    ]
    A = np.column_stack(modes)
    cov = A @ A.T + 0.04**2 * np.eye(2 * B)                         # local shape wobble
    return mean, cov


def _letters(rng, n, dt=LETTER_DT, noise=0.0):
    mean, cov = letter_prior()
    L = np.linalg.cholesky(cov)
    demos, alphas = [], []
    for i in range(n):
        w = mean.ravel() + L @ rng.normal(size=mean.size)
        alpha = float(np.clip(rng.normal(*LETTER_ALPHA), *LETTER_ALPHA_RANGE))
        steps = int(round(1.0 / (alpha * dt))) + 1
        t = dt * np.arange(steps)
        z = np.clip(alpha * t, 0.0, 1.0)
        y = _rbf(z) @ w.reshape(2, -1).T
        if noise > 0:
            y = y + rng.normal(0.0, noise, y.shape)
        demos.append(Demonstration(t=t, observed=y, controlled=np.zeros((steps, 0)), label='a',
                                   name=f'letter_{i:03d}'))
        alphas.append(alpha)
    return demos, np.array(alphas)


def phase_letters(seed: int = 0, n_train: int = 20, n_test: int = 20, noise: float = 0.0) -> LetterData:
    """Thesis 4.3.1: 40 letters from Gaussian weights and alpha, split at random into train/test."""
    rng = np.random.default_rng(seed)
    demos, alphas = _letters(rng, n_train + n_test, noise=noise)
    order = rng.permutation(len(demos))
    tr, te = order[:n_train], order[n_train:]
    train = [demos[i] for i in tr]
    return LetterData(train=train, test=[demos[i] for i in te], train_complete=list(train),
                      train_alpha=alphas[tr], test_alpha=alphas[te])


def missing_data_letters(seed: int = 0, n_train: int = 20, n_test: int = 20, gap_steps: int = 180,
                         noise: float = 0.0) -> LetterData:
    """Thesis 4.3.2: like :func:`phase_letters`, then one random block of ``gap_steps`` samples of
    every training trajectory becomes missing (NaN rows)."""
    data = phase_letters(seed, n_train, n_test, noise)
    rng = np.random.default_rng([seed, 432])
    train = []
    for d in data.train:
        T = d.t.size
        if gap_steps >= T - 1:
            raise ValueError(f'gap of {gap_steps} samples does not fit a {T}-sample trajectory')
        begin = int(rng.integers(0, T - gap_steps + 1))
        observed = d.observed.copy()
        observed[begin:begin + gap_steps] = np.nan
        train.append(Demonstration(t=d.t, observed=observed, controlled=d.controlled,
                                   label=d.label, name=d.name))
    return data._replace(train=train)
