"""Recordings as another lab would make them: the same interactions, the pair standing elsewhere
in the room, a skeleton tracker's noise, a tracker's clock, people who keep their pace less
steadily. Each corruption is seeded and takes Demonstrations to new Demonstrations (the inputs
are not changed), so that a robustness evaluation (bench/robustness.py) can run every method on
the same corrupted data. Fewer recordings is no corruption of the recordings but of a fold's
training split: the evaluation's ``EvalConfig.train_fraction`` draws it per fold.

The magnitudes are stated where they are set (:data:`DEFAULTS`) and are those of consumer
skeleton trackers, not of any one data set: where a pair stands differs by tens of cm between
sessions (the observed hand's start in another lab's Kinect recordings of NuiSI's interactions:
std 37 / 13 / 19 cm per axis), a skeleton tracker's joints wander by 1-3 cm over a tenth of a
second, and a 30 Hz tracker's stamps jitter by milliseconds and drop frames. The pace is not a
tracker's: people hold, hesitate and speed up within one movement; its magnitude (the pace off
by about a third, over about a fifth of the movement) is a stress on the linear phase z = t / T,
not a measurement of any data set.
"""

from dataclasses import dataclass

import numpy as np

from mixture_ip_ros.core.demonstration import Demonstration


@dataclass(frozen=True)
class Corruption:
    """Magnitudes of every corruption (SI units). ``offset_std``: per axis (x, y, z), the std of
    one offset per recording shared by both agents' positions; ``noise_std`` and
    ``noise_time``: stationary std and correlation time of a first-order autoregressive
    tracker noise, independent per DOF and agent; ``jitter_std``: std of each stamp around the
    tracker's nominal period; ``drop``: share of frames lost, in bursts of 1 to ``burst``
    frames; ``tempo_std`` and ``tempo_time``: std of the log pace within a movement and its correlation
    length as a share of the movement (:func:`retimed`)."""

    offset_std: tuple = (0.3, 0.15, 0.2)
    noise_std: float = 0.02
    noise_time: float = 0.1
    jitter_std: float = 0.004
    drop: float = 0.1
    burst: int = 5
    tempo_std: float = 0.3
    tempo_time: float = 0.2


DEFAULTS = Corruption()


def shifted(demos, rng, offset_std=DEFAULTS.offset_std) -> list:
    """Each recording's pair elsewhere: one offset o ~ N(0, diag(offset_std^2)) per recording
    added to the first len(offset_std) DOFs of the observed agent and, where it has as many,
    of the controlled agent (both in one frame, metres)."""
    std = np.asarray(offset_std, dtype=float)
    out = []
    for d in demos:
        o = rng.standard_normal(len(std)) * std
        obs, ctl = d.observed.copy(), d.controlled.copy()
        obs[:, :len(std)] += o
        if ctl.shape[1] >= len(std):
            ctl[:, :len(std)] += o
        out.append(Demonstration(d.t.copy(), obs, ctl, d.label, d.name))
    return out


def ar1_noise(t, n_dofs, rng, std, time_constant) -> np.ndarray:
    """(len(t), n_dofs) first-order autoregressive noise of stationary ``std`` whose
    correlation decays as exp(-dt / time_constant) over the actual spacing of the stamps."""
    out = np.empty((len(t), n_dofs))
    out[0] = rng.standard_normal(n_dofs) * std
    for i in range(1, len(t)):
        rho = np.exp(-(t[i] - t[i - 1]) / time_constant)
        out[i] = rho * out[i - 1] + np.sqrt(1 - rho ** 2) * std * rng.standard_normal(n_dofs)
    return out


def noisy(demos, rng, std=DEFAULTS.noise_std, time_constant=DEFAULTS.noise_time) -> list:
    """A tracker's noise on every DOF of both agents (:func:`ar1_noise`); missing samples stay
    missing."""
    out = []
    for d in demos:
        obs = d.observed + ar1_noise(d.t, d.n_observed_dofs, rng, std, time_constant)
        ctl = d.controlled + ar1_noise(d.t, d.n_controlled_dofs, rng, std, time_constant)
        out.append(Demonstration(d.t.copy(), obs, ctl, d.label, d.name))
    return out


def reclocked(demos, rng, jitter_std=DEFAULTS.jitter_std, drop=DEFAULTS.drop,
              burst=DEFAULTS.burst) -> list:
    """A tracker's clock: each stamp off its nominal time by N(0, jitter_std^2) (kept
    increasing: at least a tenth of the nominal period apart), and about ``drop`` of the frames
    lost in bursts of 1 to ``burst`` frames; the first and last frames (onset and end) stay."""
    out = []
    for d in demos:
        n = len(d.t)
        period = float(np.median(np.diff(d.t)))
        keep = np.ones(n, dtype=bool)
        mean_burst = (1 + burst) / 2
        for start in np.flatnonzero(rng.random(n) < drop / mean_burst):
            keep[start:start + int(rng.integers(1, burst + 1))] = False
        keep[0] = keep[-1] = True
        t = d.t + rng.standard_normal(n) * jitter_std
        t[0] = d.t[0]
        for i in range(1, n):
            t[i] = max(t[i], t[i - 1] + 0.1 * period)
        t, rows = t[keep], np.flatnonzero(keep)
        out.append(Demonstration(t - t[0], d.observed[rows], d.controlled[rows], d.label,
                                 d.name))
    return out


def retimed(demos, rng, std=DEFAULTS.tempo_std, correlation=DEFAULTS.tempo_time) -> list:
    """People's pace within a movement: every sample of a recording keeps its values (both
    people's: they hold or hurry together) and gets a new stamp, so that the onset and the end,
    and with them the duration T, stay where they were. Between samples i and i + 1 the time
    taken is c (u[i+1] - u[i]) exp(-r[i]), u = t / T the movement's progress and c the constant
    that keeps T; the log pace r is :func:`ar1_noise` over u (std ``std``, correlation
    exp(-du / ``correlation``)). A linear phase z = t / T then misplaces every sample. With
    ``std`` 0 every recording is returned as it was (its stamps not even rounded)."""
    out = []
    for d in demos:
        if std == 0:
            out.append(Demonstration(d.t.copy(), d.observed.copy(), d.controlled.copy(), d.label,
                                     d.name))
            continue
        T = d.t[-1]
        u = d.t / T
        r = ar1_noise(u[:-1], 1, rng, std, correlation)[:, 0]
        step = np.diff(u) * np.exp(-r)
        t = np.concatenate([[0.0], np.cumsum(step)]) * (T / step.sum())
        t[-1] = T
        out.append(Demonstration(t, d.observed.copy(), d.controlled.copy(), d.label, d.name))
    return out


KNOWN = ('offset', 'noise', 'clock', 'tempo')


def corrupted(demos, which, seed: int = 0, magnitudes: Corruption = DEFAULTS) -> list:
    """``demos`` with the corruptions named in ``which`` (of :data:`KNOWN`), each from its own
    stream of ``seed`` (the streams in that order, so that one corruption's draws do not depend
    on which others are asked for); applied in the order they happen: the people's pace first,
    then the tracker's clock changes the stamps, its noise runs over them, then the pair is
    moved."""
    unknown = set(which) - set(KNOWN)
    if unknown:
        raise ValueError(f'unknown corruptions {sorted(unknown)}; known: {", ".join(KNOWN)}')
    streams = np.random.SeedSequence(seed).spawn(len(KNOWN))
    out = list(demos)
    if 'tempo' in which:
        out = retimed(out, np.random.default_rng(streams[3]), magnitudes.tempo_std,
                      magnitudes.tempo_time)
    if 'clock' in which:
        out = reclocked(out, np.random.default_rng(streams[2]), magnitudes.jitter_std,
                        magnitudes.drop, magnitudes.burst)
    if 'noise' in which:
        out = noisy(out, np.random.default_rng(streams[1]), magnitudes.noise_std,
                    magnitudes.noise_time)
    if 'offset' in which:
        out = shifted(out, np.random.default_rng(streams[0]), magnitudes.offset_std)
    return out
