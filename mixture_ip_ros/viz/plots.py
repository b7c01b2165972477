"""Figures of `mixture-ip evaluate` (matplotlib, Agg backend, PNG), after the thesis's figures."""

from __future__ import annotations

from pathlib import Path
import textwrap

import matplotlib

matplotlib.use('Agg')

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from mixture_ip_ros.core.interaction import trajectory_distribution  # noqa: E402
from mixture_ip_ros.io.files import write_atomic  # noqa: E402

LABEL_COLORS = {'plate': 'tab:blue', 'screw': 'tab:orange', 'screwdriver': 'tab:green',
                'left': 'tab:blue', 'right': 'tab:red'}
DPI = 110


def _color(label, i=0):
    return LABEL_COLORS.get(label, f'C{i % 10}')


def save_figure(fig, path, dpi=DPI):
    """Write ``fig`` to ``path`` (format from its suffix) atomically, and close it."""
    path = Path(path)
    try:
        write_atomic(path, lambda f: fig.savefig(f, dpi=dpi, format=path.suffix.lstrip('.')))
    finally:
        plt.close(fig)





def rms_vs_k(path, candidates, rms, chosen, title, ylabel='RMS error', compared=None):
    """Figs. 8 and 10: mean and standard deviation over folds of the LOO RMS, per K."""
    fig, ax = plt.subplots(figsize=(6.4, 4.2), constrained_layout=True)
    mean, std = rms.mean(axis=1), rms.std(axis=1)
    ax.errorbar(candidates, mean, yerr=std, fmt='o-', capsize=4, color='k', label='mean +- std')
    ax.plot(candidates, np.median(rms, axis=1), 'd--', color='tab:blue', ms=5, label='median')
    for n, (K, r) in enumerate(zip(candidates, rms)):
        ax.plot(np.full(r.size, K) + np.linspace(-0.12, 0.12, r.size), r, '.', color='0.7', ms=3,
                zorder=0, label='single folds' if n == 0 else None)
    i = list(candidates).index(chosen)
    ax.plot([chosen], [mean[i]], 'o', ms=12, mfc='none', mec='tab:red', mew=2,
            label=f'selected K = {chosen} (1-SE rule)')
    if compared is not None and compared != chosen:
        j = list(candidates).index(compared)
        ax.plot([compared], [mean[j]], 's', ms=12, mfc='none', mec='tab:green', mew=2,
                label=f'K = {compared} shown in Fig. 7')
    ax.set_xlabel('number of mixture components K')
    ax.set_ylabel(ylabel)
    ax.set_xticks(list(candidates))
    top = np.percentile(rms, 98)
    ax.set_ylim(0, max(top, (mean + std).max()) * 1.05)
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=8, loc='best', framealpha=0.9)
    ax.grid(alpha=0.3)
    save_figure(fig, path)


def _dof_names(model):
    return ['wrist x [m]', 'wrist y [m]', 'wrist z [m]'] + [
        f'joint {j + 1} [rad]' for j in range(model.n_controlled_)]


def box_components_and_posterior(path, model, demos, comp_labels, example, n_joints=4):
    """Fig. 11: upper row the mixture components (mean +- 2 sigma) over the demonstrations;
    lower row one leave-one-out test: prior (grey), posterior given the final wrist position (red),
    ground truth (black), observation (blue asterisk). Wrist xyz and the first ``n_joints``
    joints."""
    dofs = list(range(model.n_observed_)) + [model.n_observed_ + j for j in range(n_joints)]
    names = _dof_names(model)
    zg = np.linspace(0, 1, 100)
    fig, axes = plt.subplots(2, len(dofs), figsize=(2.3 * len(dofs), 5.4), constrained_layout=True)
    for d in demos:
        z = d.phase
        Y = np.hstack([d.observed, d.controlled])
        for c, j in enumerate(dofs):
            axes[0, c].plot(z, Y[:, j], color='0.75', lw=0.5, zorder=0)
    for k in range(model.n_components):
        dist = trajectory_distribution(model.means_[k], model.covariances_[k], model.basis_, zg,
                                       dofs=dofs)
        sd = np.sqrt(np.einsum('tii->ti', dist['position_cov']))
        col = _color(comp_labels[k], k)
        for c in range(len(dofs)):
            m = dist['position'][:, c]
            axes[0, c].fill_between(zg, m - 2 * sd[:, c], m + 2 * sd[:, c], color=col, alpha=0.25)
            axes[0, c].plot(zg, m, color=col, lw=1.5,
                            label=f'{k}: {comp_labels[k]}' if c == 0 else None)
    axes[0, 0].legend(fontsize=7, loc='best')
    if example is not None:
        fold_model, test, y_obs, z_obs, k = example
        for kk in range(fold_model.n_components):
            dist = trajectory_distribution(fold_model.means_[kk], fold_model.covariances_[kk],
                                           fold_model.basis_, zg, dofs=dofs)
            sd = np.sqrt(np.einsum('tii->ti', dist['position_cov']))
            for c in range(len(dofs)):
                m = dist['position'][:, c]
                axes[1, c].fill_between(zg, m - 2 * sd[:, c], m + 2 * sd[:, c], color='0.6',
                                        alpha=0.3, lw=0)
        _, mean, cov = fold_model.condition(z_obs, y_obs, component=k)
        dist = trajectory_distribution(mean, cov, fold_model.basis_, zg, dofs=dofs)
        sd = np.sqrt(np.maximum(np.einsum('tii->ti', dist['position_cov']), 0))
        z = test.phase
        Y = np.hstack([test.observed, test.controlled])
        for c, j in enumerate(dofs):
            ax = axes[1, c]
            m = dist['position'][:, c]
            ax.fill_between(zg, m - 2 * sd[:, c], m + 2 * sd[:, c], color='tab:red', alpha=0.35)
            ax.plot(zg, m, color='tab:red', lw=1.5)
            ax.plot(z, Y[:, j], color='k', lw=1.2)
            if j < fold_model.n_observed_:
                ax.plot(z_obs, y_obs[:, j], '*', color='tab:blue', ms=12)
        axes[1, 0].set_title(f'held out: {test.name} ({test.label})', fontsize=8, loc='left')
    for c, j in enumerate(dofs):
        axes[0, c].set_title(names[j], fontsize=9)
        axes[1, c].set_xlabel('phase z')
    axes[0, 0].set_ylabel('components (mean +- 2 sd)')
    axes[1, 0].set_ylabel('posterior | final wrist')
    fig.suptitle('Box assembly: mixture components (upper) and one leave-one-out posterior '
                 '(lower), thesis Fig. 11', fontsize=10)
    save_figure(fig, path)


def box_online(path, fractions, correct, err, labels, final_correct, final_err):
    """Beyond the thesis: component selection accuracy and hand error vs observed fraction of the
    human's motion (online estimator, phase unknown), with the final-position result for
    reference."""
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.2), constrained_layout=True)
    x = 100 * np.asarray(fractions)
    a1.plot(x, 100 * correct.mean(axis=0), 'o-', color='k', label='all')
    for lbl in sorted(set(labels)):
        sel = labels == lbl
        a1.plot(x, 100 * correct[sel].mean(axis=0), '.--', color=_color(lbl), label=lbl)
    a1.axhline(100 * np.mean(final_correct), color='tab:purple', ls=':',
               label=f'final wrist position, phase known ({100 * np.mean(final_correct):.0f} %)')
    a1.set_ylim(0, 105)
    a1.set_xlabel('observed part of the human motion [%]')
    a1.set_ylabel('correct component [%] (leave-one-out)')
    a1.set_title('Component selection, online estimator', fontsize=10)
    a1.legend(fontsize=8, loc='lower right')
    a1.grid(alpha=0.3)
    for lbl in sorted(set(labels)):
        sel = labels == lbl
        m = 100 * np.nanmean(err[sel], axis=0)
        s = 100 * np.nanstd(err[sel], axis=0)
        a2.plot(x, m, 'o-', color=_color(lbl), label=f'{lbl}: mean, band +- 2 sd')
        a2.fill_between(x, np.maximum(m - 2 * s, 0), m + 2 * s, color=_color(lbl), alpha=0.12)
        fe = 100 * final_err[sel]
        a2.errorbar([110], [fe.mean()], yerr=[[min(2 * fe.std(), fe.mean())], [2 * fe.std()]],
                    fmt='s', color=_color(lbl), capsize=3)
    a2.set_ylim(bottom=0)
    a2.set_xticks([0, 20, 40, 60, 80, 100, 110], ['0', '20', '40', '60', '80', '100', 'final'])
    a2.set_xlabel('observed part of the human motion [%]')
    a2.set_ylabel('robot hand position error [cm]')
    a2.set_title('Hand error (FK, predicted vs demonstrated final posture);\n'
                 'squares: from the last wrist sample with the phase known (thesis)', fontsize=9)
    a2.legend(fontsize=8)
    a2.grid(alpha=0.3)
    save_figure(fig, path)


def hand_error_hist(path, final_err, labels):
    """Per-pattern leave-one-out hand errors from the final wrist position (thesis 3.4.2)."""
    pats = sorted(set(labels))
    fig, ax = plt.subplots(figsize=(6.4, 4.0), constrained_layout=True)
    for i, lbl in enumerate(pats):
        e = 100 * final_err[labels == lbl]
        ax.plot(np.full(e.size, i) + np.linspace(-0.15, 0.15, e.size), e, 'o', color=_color(lbl),
                alpha=0.7)
        ax.errorbar([i + 0.3], [e.mean()], yerr=[2 * e.std()], fmt='s', color='k', capsize=4)
        ax.annotate(f'{e.mean():.1f} +- {2 * e.std():.1f}', (i + 0.33, e.mean()), fontsize=8)
    ax.set_xticks(range(len(pats)), pats)
    ax.set_ylabel('hand position error [cm]')
    ax.set_title('Hand error by FK, leave-one-out (mean +- 2 sd); thesis: plate 3.2 +- 2.6, '
                 'screwdriver 2.1 +- 2.3', fontsize=9)
    ax.grid(alpha=0.3)
    save_figure(fig, path)


def pole_paths(path, true_paths, single, mixture, K, pole_xy, pole_radius, labels):
    """Fig. 7: top view of the flange paths (FK of the predicted joint trajectories, leave-one-out)
    of one Gaussian (a) and the mixture (b) over the demonstrated paths, with the pole."""
    fig, axes = plt.subplots(1, 2, figsize=(10, 6.2), constrained_layout=True)
    allp = np.vstack(true_paths + list(single) + list(mixture))[:, :2]
    lo, hi = allp.min(axis=0) - 0.03, allp.max(axis=0) + 0.03
    for ax, preds, title in ((axes[0], single, '(a) one Gaussian (Interaction ProMP)'),
                             (axes[1], mixture, f'(b) mixture, K = {K}')):
        for p in true_paths:
            ax.plot(p[:, 0], p[:, 1], color='0.65', lw=1.0, zorder=1)
        for p, lbl in zip(preds, labels):
            ax.plot(p[:, 0], p[:, 1], color=_color(lbl), lw=1.2, alpha=0.85, zorder=2)
            ax.plot(p[-1, 0], p[-1, 1], 'o', color=_color(lbl), ms=3, zorder=3)
        ax.add_patch(plt.Circle(pole_xy, pole_radius, color='k', zorder=4))
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_aspect('equal')
        ax.set_xlabel('x [m]')
        ax.set_title(title, fontsize=10)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel('y [m]')
    axes[0].plot([], [], color='0.65', label='demonstrated (ground truth)')
    for lbl in sorted(set(labels)):
        axes[0].plot([], [], color=_color(lbl), label=f'predicted, true side {lbl}')
    axes[0].plot([], [], 'ko', label='pole')
    axes[0].legend(fontsize=8, loc='best')
    fig.suptitle('Pole: predicted flange paths (top view), leave-one-out, thesis Fig. 7',
                 fontsize=10)
    save_figure(fig, path)


def letter_rms(path_per, path_mean, fractions, R, title):
    """Figs. 26-27: RMS vs observed part, per test trajectory and mean +- std."""
    x = 100 * np.asarray(fractions)
    fig, ax = plt.subplots(figsize=(6.4, 4.2), constrained_layout=True)
    for i, r in enumerate(R):
        ax.plot(x, r, lw=1, color=f'C{i % 10}')
    ax.set_xlabel('observed part of the test trajectory [%]')
    ax.set_ylabel('RMS error')
    ax.set_title(f'{title}: each test trajectory', fontsize=10)
    ax.grid(alpha=0.3)
    save_figure(fig, path_per)
    fig, ax = plt.subplots(figsize=(6.4, 4.2), constrained_layout=True)
    m, s = np.nanmean(R, axis=0), np.nanstd(R, axis=0)
    ax.plot(x, m, color='k', label='mean')
    ax.fill_between(x, np.maximum(m - s, 0), m + s, color='0.6', alpha=0.4, label='+- 1 std')
    ax.set_xlabel('observed part of the test trajectory [%]')
    ax.set_ylabel('RMS error')
    ax.set_title(f'{title}: mean and std', fontsize=10)
    ax.legend()
    ax.grid(alpha=0.3)
    save_figure(fig, path_mean)


def letter_completion_panels(path, test, snaps, train, true_alpha):
    """Figs. 16-25: completion of one test letter after 5, 10, 20, 40, 60 % observed: the letter
    (x-y), x(t) and y(t) with mean +- 2 sd, and p(alpha | D) with the true alpha."""
    keys = sorted(snaps)
    fig, axes = plt.subplots(4, len(keys), figsize=(3.0 * len(keys), 10), constrained_layout=True)
    axes = np.atleast_2d(axes).reshape(4, len(keys))
    Y = test.observed
    for c, f in enumerate(keys):
        mean, cov, post, alphas, last = snaps[f]
        sd = np.sqrt(np.maximum(np.einsum('tii->ti', cov), 0))
        ax = axes[0, c]
        for d in train:
            ax.plot(d.observed[:, 0], d.observed[:, 1], color='0.85', lw=0.6, zorder=0)
        ax.plot(Y[:, 0], Y[:, 1], color='tab:blue', lw=1.2, label='ground truth')
        ax.plot(Y[:last + 1, 0], Y[:last + 1, 1], '*', color='tab:blue', ms=3, label='observed')
        ax.plot(mean[:, 0], mean[:, 1], color='tab:red', lw=1.5, label='prediction')
        ax.set_aspect('equal')
        ax.set_title(f'{100 * f:.0f} % observed', fontsize=10)
        for r, dof in ((1, 0), (2, 1)):
            ax = axes[r, c]
            ax.fill_between(test.t, mean[:, dof] - 2 * sd[:, dof], mean[:, dof] + 2 * sd[:, dof],
                            color='tab:red', alpha=0.3)
            ax.plot(test.t, mean[:, dof], color='tab:red')
            ax.plot(test.t, Y[:, dof], color='tab:blue')
            ax.plot(test.t[:last + 1], Y[:last + 1, dof], '*', color='tab:blue', ms=2)
            ax.set_xlabel('t [s]')
            ax.set_ylabel('xy'[dof])
        ax = axes[3, c]
        ax.bar(np.arange(len(alphas)), post, color='0.4')
        ax.axvline(np.argmin(np.abs(alphas - true_alpha)), color='tab:red',
                   label='true alpha (nearest sample)')
        ax.set_xlabel('alpha sample index')
        ax.set_ylabel('p(alpha | D)')
    axes[0, 0].legend(fontsize=7)
    axes[3, 0].legend(fontsize=7)
    fig.suptitle('Phase estimation and completion of a test letter (thesis Figs. 16-25)',
                 fontsize=11)
    save_figure(fig, path)


def alpha_error(path, fractions, A, true_alpha, step):
    """Relative error of the MAP alpha vs observed part (mean, and each test trajectory)."""
    x = 100 * np.asarray(fractions)
    rel = np.abs(A - true_alpha[:, None]) / true_alpha[:, None]
    fig, ax = plt.subplots(figsize=(6.4, 4.2), constrained_layout=True)
    for r in rel:
        ax.plot(x, 100 * r, color='0.7', lw=0.7)
    ax.plot(x, 100 * np.nanmean(rel, axis=0), color='k', lw=2, label='mean')
    ax.axhline(100 * step / np.mean(true_alpha), color='tab:red', ls=':',
               label='one alpha grid step (relative)')
    ax.set_ylim(0, min(30, max(3 * 100 * step / np.mean(true_alpha), 100 * np.nanmax(rel))))
    ax.set_xlabel('observed part of the test trajectory [%]')
    ax.set_ylabel('|alpha* - alpha| / alpha [%]')
    ax.set_title('Phase speed estimate (MAP of 50 samples)', fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    save_figure(fig, path)


def missing_data(path_rms, path_ll, path_recon, fractions, R_em, R_reg, ll, complete, demo, recon):
    """Fig. 42 (RMS vs observed part, EM vs regression), Fig. 43 (EM log-likelihood per
    iteration) and Figs. 36-37 (a training letter with a gap as each method reconstructs it)."""
    x = 100 * np.asarray(fractions)
    fig, ax = plt.subplots(figsize=(6.4, 4.2), constrained_layout=True)
    for R, name, col in ((R_reg, 'linear regression', 'tab:orange'), (R_em, 'EM', 'tab:blue')):
        m, s = np.nanmean(R, axis=0), np.nanstd(R, axis=0)
        ax.plot(x, m, color=col, label=f'{name} (mean +- std)')
        ax.fill_between(x, np.maximum(m - s, 0), m + s, color=col, alpha=0.25)
    ax.set_xlabel('observed part of the test trajectory [%]')
    ax.set_ylabel('RMS error')
    ax.set_title('Training with missing data: EM vs regression (thesis Fig. 42)', fontsize=10)
    ax.legend()
    ax.grid(alpha=0.3)
    save_figure(fig, path_rms)

    fig, ax = plt.subplots(figsize=(6.4, 4.2), constrained_layout=True)
    ax.plot(np.arange(1, len(ll) + 1), ll, 'o-', color='k', ms=3)
    ax.set_xlabel('EM iteration')
    ax.set_ylabel('log-likelihood of the training data (penalised)')
    ax.set_title('EM learning progress (thesis Fig. 43)', fontsize=10)
    ax.grid(alpha=0.3)
    save_figure(fig, path_ll)

    fig, axes = plt.subplots(1, 2, figsize=(9, 4.4), constrained_layout=True)
    for ax, (name, title) in zip(axes, (('regression', 'linear regression (Fig. 36)'),
                                        ('em', 'EM (Fig. 37)'))):
        ax.plot(complete.observed[:, 0], complete.observed[:, 1], color='0.8', lw=3,
                label='complete (not seen)')
        ax.plot(demo.observed[:, 0], demo.observed[:, 1], '.', color='tab:blue', ms=2,
                label='observed samples')
        ax.plot(recon[name][:, 0], recon[name][:, 1], color='tab:red', lw=1.5,
                label='approximation')
        ax.set_aspect('equal')
        ax.set_title(title, fontsize=10)
    axes[0].legend(fontsize=8)
    fig.suptitle(f'Training letter {demo.name} with {int(np.isnan(demo.observed[:, 0]).sum())} '
                 'missing samples', fontsize=10)
    save_figure(fig, path_recon)


def accuracy_vs_fraction(path, fractions, curves, levels, title, chance=None, points=None):
    """Accuracy of every method vs the fraction of the movement observed. ``curves``: {name:
    accuracies per fraction}; ``levels``: {name: one accuracy} of methods that see the whole
    series (drawn as horizontal lines); ``points``: {name: (fraction, accuracy)}, single
    results (drawn as stars)."""
    fig, ax = plt.subplots(figsize=(10.5, 4.6), constrained_layout=True)
    markers = 'osd^v<>'
    for i, (name, acc) in enumerate(curves.items()):
        ax.plot(100 * np.asarray(fractions), 100 * np.asarray(acc, dtype=float),
                marker=markers[i % len(markers)], color=f'C{i}', label=name)
    for j, (name, acc) in enumerate(levels.items()):
        ax.axhline(100 * acc, color=f'C{len(curves) + j}', ls='--', lw=1.5,
                   label=f'{name} (whole series)')
    for j, (name, (f, acc)) in enumerate((points or {}).items()):
        ax.plot([100 * f], [100 * acc], marker='*', ms=13, ls='none',
                color=f'C{len(curves) + len(levels) + j}', label=name)
    if chance is not None:
        ax.axhline(100 * chance, color='0.6', ls=':', lw=1, label='chance')
    ax.set_xlabel('observed part of the movement [%]')
    ax.set_ylabel('accuracy [%]')
    ax.set_ylim(0, 100)
    ax.set_xticks(100 * np.asarray(fractions))
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=8, loc='center left', bbox_to_anchor=(1.01, 0.5))
    ax.grid(alpha=0.3)
    save_figure(fig, path)


def clusters_vs_labels(path, counts, component_names, class_names, title):
    """How the training demonstrations of each class (columns) fall into the unsupervised
    components (rows): a count matrix."""
    counts = np.asarray(counts)
    fig, ax = plt.subplots(figsize=(max(5.0, 1.6 + 0.55 * len(class_names)),
                                    max(3.2, 1.4 + 0.42 * len(counts))),
                           constrained_layout=True)
    im = ax.imshow(counts, cmap='Blues', aspect='auto')
    for (r, c), v in np.ndenumerate(counts):
        if v:
            ax.text(c, r, str(v), ha='center', va='center', fontsize=8,
                    color='white' if v > 0.6 * counts.max() else 'black')
    ax.set_xticks(range(len(class_names)))
    ax.set_xticklabels(class_names)
    ax.set_yticks(range(len(counts)))
    ax.set_yticklabels([f'{k}: {n}' for k, n in enumerate(component_names)], fontsize=8)
    ax.set_xlabel('true class (not used in fitting)')
    ax.set_ylabel('component: majority class')
    ax.set_title(title, fontsize=10)
    fig.colorbar(im, ax=ax, shrink=0.8, label='training demonstrations')
    save_figure(fig, path)


def k_curve(path, candidates, mean, se, chosen, title, note=''):
    """A criterion for K (higher is better) vs K: its mean per demonstration relative to the
    first candidate, +- its standard error, the chosen K circled."""
    mean = np.asarray(mean, dtype=float) - float(mean[0])
    fig, ax = plt.subplots(figsize=(6.4, 4.2), constrained_layout=True)
    ax.errorbar(candidates, mean, yerr=se, fmt='o-', capsize=4, color='k',
                label='mean +- s.e. over held-out demonstrations')
    i = list(candidates).index(chosen)
    ax.plot([chosen], [mean[i]], 'o', ms=12, mfc='none', mec='tab:red', mew=2,
            label=f'selected K = {chosen}')
    ax.set_xlabel('number of mixture components K')
    ax.set_ylabel(f'relative to K = {candidates[0]} [nats per demonstration]')
    ax.set_xticks(list(candidates))
    ax.set_title('\n'.join([title] + textwrap.wrap(note, 90)), fontsize=9)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    save_figure(fig, path)


def errors_vs_fraction(path, fractions, errors, title, ylabel):
    """Mean error of every method vs the fraction of the movement observed, with the standard
    error of the mean as a band. ``errors``: {name: (recordings, fractions) array, NaN where
    not defined}."""
    fig, ax = plt.subplots(figsize=(9.5, 4.4), constrained_layout=True)
    f = 100 * np.asarray(fractions)
    for i, (name, e) in enumerate(errors.items()):
        e = np.asarray(e, dtype=float)
        mean = np.nanmean(e, axis=0)
        se = np.nanstd(e, axis=0) / np.sqrt(np.maximum(np.sum(~np.isnan(e), axis=0), 1))
        ax.plot(f, mean, marker='osd^v'[i % 5], color=f'C{i}', label=name)
        ax.fill_between(f, mean - se, mean + se, color=f'C{i}', alpha=0.15)
    ax.set_xlabel('observed part of the movement [%]')
    ax.set_ylabel(ylabel)
    ax.set_xticks(f)
    ax.set_ylim(bottom=0)
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=8, loc='center left', bbox_to_anchor=(1.01, 0.5))
    ax.grid(alpha=0.3)
    save_figure(fig, path)


def partner_paths(path, examples, scale=100.0, unit='cm', dof_names=None):
    """Predicted against recorded controlled agent, one row per example (one recording per
    interaction): (demonstration, rows predicted, prediction (m, Q), name of the component),
    each DOF against time; the observed agent's recorded path beside it. ``scale`` turns the
    DOFs into ``unit`` (the y axes' unit); ``dof_names`` (observed names, controlled names)
    name the DOFs' colours in the key (default: DOF 1, DOF 2, ...)."""
    if not examples:
        return
    Q = examples[0][0].n_controlled_dofs
    P = examples[0][0].n_observed_dofs
    observed_names, controlled_names = dof_names or (
        [f'DOF {j + 1}' for j in range(P)], [f'DOF {j + 1}' for j in range(Q)])
    fig, axes = plt.subplots(len(examples), 2, figsize=(11, 2.3 * len(examples)),
                             constrained_layout=True, squeeze=False)
    for r, (demo, rest, pred, chosen) in enumerate(examples):
        ax_o, ax_c = axes[r]
        for j in range(P):
            ax_o.plot(demo.t, scale * demo.observed[:, j], color=f'C{j}', lw=1,
                      label=observed_names[j] if r == 0 else None)
        ax_o.axvspan(demo.t[0], demo.t[rest[0]] if len(rest) else demo.t[-1], color='0.9')
        ax_o.set_ylabel(f'{demo.label}\nobserved [{unit}]', fontsize=8)
        for j in range(Q):
            ax_c.plot(demo.t, scale * demo.controlled[:, j], color=f'C{j}', lw=1,
                      label=controlled_names[j] if r == 0 else None)
            ax_c.plot(demo.t[rest], scale * pred[:, j], color=f'C{j}', lw=2, ls='--')
        ax_c.plot([], [], color='k', lw=1, label='recorded')
        ax_c.plot([], [], color='k', lw=2, ls='--', label=f'predicted ({chosen})')
        ax_c.axvspan(demo.t[0], demo.t[rest[0]] if len(rest) else demo.t[-1], color='0.9')
        ax_c.set_ylabel(f'controlled [{unit}]', fontsize=8)
        ax_c.legend(fontsize=7, loc='center left', bbox_to_anchor=(1.01, 0.5))
    axes[0, 0].legend(fontsize=7, loc='center left', bbox_to_anchor=(1.01, 0.5),
                      title='colour', title_fontsize=7)
    axes[0, 0].set_title('observed agent (grey: the part observed)', fontsize=9)
    axes[0, 1].set_title('controlled agent: recorded (solid) and predicted (dashed)',
                         fontsize=9)
    axes[-1, 0].set_xlabel('t [s]')
    axes[-1, 1].set_xlabel('t [s]')
    save_figure(fig, path)
