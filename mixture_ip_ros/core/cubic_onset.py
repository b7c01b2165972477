"""When a hand left rest, dated from the positions around it (core.segmentation's dating of
an onset, and in reversed time of an end).

A smooth movement leaves rest with zero velocity and acceleration, so its displacement grows
as (t - t_onset)^3: the positions are fitted with p(t) = b + a (t - t_onset)^3_+ (per-axis b,
a; t_onset shared, by grid search, O(samples x grid) once per movement). The profile is only
cubic near a movement's ends, so a long slow reach is dated less precisely than a brisk one.
"""

import math

import numpy as np


def fit_cubic_onset(t, positions, lo: float, hi: float, step: float = 0.01,
                    drift: bool = False) -> float:
    """Least-squares onset time of p(t) = b + a (t - t_onset)^3_+ with t_onset in [lo, hi]
    (``drift``: p(t) = b + c t + a (t - t_onset)^3_+, a hand drifting at a constant velocity c
    before it leaves rest).

    ``t``: (N,) times, ``positions``: (N, D); b (c) and a are fitted per column for each
    candidate t_onset (closed form). The grid of ``step`` seconds is searched on at most
    ~250 of the samples, then refined to step / 10 on all of them.
    """
    t = np.asarray(t, dtype=float)
    x = np.asarray(positions, dtype=float)
    if x.ndim == 1:
        x = x[:, None]
    if t.ndim != 1 or t.size < 3 or x.shape[0] != t.size:
        raise ValueError(f'fit_cubic_onset: need at least 3 times and one position row per time, '
                         f'got t {t.shape}, positions {x.shape}')
    span = hi - lo
    if not span >= 0:
        raise ValueError(f'fit_cubic_onset: empty interval [{lo}, {hi}]')
    if span == 0:
        return lo
    tr = t - lo
    xc = x - x.mean(axis=0)

    def best_with_drift(taus, stride):
        ts, xs = tr[::stride], xc[::stride]
        tc = ts - ts.mean()
        tt = max(float(tc @ tc), 1e-300)
        xs = xs - np.outer(tc, tc @ xs / tt)                # project out [1, t] (x is centred)
        f = np.clip(ts[None, :] - taus[:, None], 0.0, None) ** 3
        f = f - f.mean(axis=1, keepdims=True)
        f = f - np.outer(f @ tc / tt, tc)
        sff = np.einsum('gn,gn->g', f, f)
        sfx = f @ xs
        ok = sff > 1e-30 * max(1.0, float(sff.max()))
        gain = np.where(ok, np.einsum('gd,gd->g', sfx, sfx) / np.where(ok, sff, 1.0), 0.0)
        return float(taus[int(np.argmax(gain))])

    def best(taus, stride):
        if drift:
            return best_with_drift(taus, stride)
        ts, xs = tr[::stride], xc[::stride]
        after = ts > taus[0]  # earlier samples have f = 0 for every candidate
        f = np.clip(ts[after][None, :] - taus[:, None], 0.0, None) ** 3
        sf = f.sum(axis=1)
        sff = np.einsum('gn,gn->g', f, f) - sf * sf / ts.size
        sfx = f @ xs[after] - sf[:, None] * xs.mean(axis=0)
        # Variance explained by the cubic; zero where the candidate is after every sample.
        ok = sff > 1e-30
        gain = np.where(ok, np.einsum('gd,gd->g', sfx, sfx) / np.where(ok, sff, 1.0), 0.0)
        return float(taus[int(np.argmax(gain))])

    n = max(2, int(math.ceil(span / step)) + 1)
    coarse = np.linspace(0.0, span, n)
    tau = best(coarse, max(1, t.size // 250))
    h = coarse[1] - coarse[0]
    tau = best(np.linspace(max(0.0, tau - 2 * h), min(span, tau + 2 * h), 41), 1)
    return lo + tau
