"""Any agent layout (observed >= 1 DOF, controlled >= 0) through Demonstration, training, the
model file, the command line and the online estimator; K for every layout; the tied noise."""

import json

import numpy as np
import pytest
from scipy.special import logsumexp
from scipy.stats import multivariate_normal, norm

from conftest import heldout_loglik
from mixture_ip_ros.app.cli import main
from mixture_ip_ros.app.evaluation import subsampled
from mixture_ip_ros.app.training import train, train_to_file
from mixture_ip_ros.core.basis import GaussianBasis
from mixture_ip_ros.core.demonstration import Demonstration, Layout
from mixture_ip_ros.core.gmm import gmm_log_prob, gmm_responsibilities
from mixture_ip_ros.core.mixture import MixtureIProMP
from mixture_ip_ros.core.selection import PRIOR_SCALES
from mixture_ip_ros.core.selection import loo_rms_by_components, selection_curve
from mixture_ip_ros.core.online import OnlineEstimator
from mixture_ip_ros.core.promp import observation_stats
from mixture_ip_ros.io.csv_files import CsvError, load_csv_dataset, write_csv_demonstration
from mixture_ip_ros.io.model_file import load_model, model_layout

from mixture_ip_ros.scenarios.folders import generate
from mixture_ip_ros.scenarios.synthetic import mixture_demos


def _layout(P, Q):
    return Layout(tuple(f'o{i}' for i in range(P)), tuple(f'c{j}' for j in range(Q)),
                  ('m',) * P, ('rad',) * Q)


@pytest.mark.parametrize('P, Q', [(1, 0), (2, 0), (1, 2), (4, 1), (3, 7)])
@pytest.mark.decision
def test_layout_trains_saves_loads_and_recognises_online(tmp_path, P, Q):
    # Seed 1: in every layout K = 3 beats 2 by at least 2.3 paired standard errors (the
    # plateau's edge is 2) and K = 4 is at most 0.8 above 3 (the one-standard-error step's edge
    # is 1): K is decided by the data, not by rounding (test_cpu_kernels checks the kernels).
    demos, labels, _, _ = mixture_demos(seed=1, n_obs=P, n_ctrl=Q)
    layout = _layout(P, Q)
    model, info = train_to_file(demos, tmp_path / 'm.npz', layout=layout, candidates=(1, 2, 3, 4),
                                n_basis=8)
    assert info['n_components'] == 3 and info['selection']['clear_optimum']
    assert info['selection']['criterion'] == 'patterns'
    loaded, meta = load_model(tmp_path / 'm.npz', observed_names=layout.observed,
                              controlled_names=layout.controlled)
    assert model_layout(meta) == layout
    assert meta['observed_units'] == ['m'] * P and meta['controlled_units'] == ['rad'] * Q
    correct = []
    for i in range(0, len(demos), 3):
        d = demos[i]
        a, b = OnlineEstimator(model), OnlineEstimator(loaded)
        for t, y in zip(d.t[:len(d.t) // 2], d.observed[:len(d.t) // 2]):
            a.update(t, y)
            b.update(t, y)
        assert np.array_equal(a.joint_posterior(), b.joint_posterior())
        k = int(np.argmax(b.component_posterior()))
        correct.append(k == int(np.argmax(model.resp_[i])))
        pred = b.predict([0.5, 1.0])
        assert pred['controlled']['position'].shape == (2, Q)
        assert pred['observed']['position'].shape == (2, P)
        rest, cov = b.predict_at_rest(d.observed[-1])
        assert rest.shape == (Q,) and cov.shape == (Q, Q)
        # a single-agent model predicts the observed agent's rest from half the movement
        if Q == 0:
            assert np.sqrt(np.mean((pred['observed']['position'][1] - d.observed[-1]) ** 2)) < 0.1
    assert np.mean(correct) == 1.0


def test_demonstration_accepts_1d_arrays_and_no_controlled_agent():
    d = Demonstration(np.linspace(0, 1, 11), np.arange(11.0))
    assert d.observed.shape == (11, 1) and d.controlled.shape == (11, 0)
    assert d.n_controlled_dofs == 0 and d.phase[-1] == 1.0
    with pytest.raises(ValueError, match=r't must start at the onset.*t\[0\] = 1'):
        Demonstration(np.linspace(1, 6, 11), np.arange(11.0))
    with pytest.raises(ValueError, match='at least one DOF'):
        Demonstration(np.linspace(0, 1, 11), np.zeros((11, 0)))


@pytest.mark.parametrize('Q', [0, 3])
@pytest.mark.decision
def test_heldout_loglik_finds_the_sampled_number_of_components(Q):
    demos = mixture_demos(seed=5, n_obs=2, n_ctrl=Q)[0]
    ll = heldout_loglik(demos, [1, 2, 3, 4, 5], n_basis=8)['scores']
    curve = selection_curve(ll, higher_is_better=True, paired=True)
    assert [1, 2, 3, 4, 5][curve['index']] == 3 and curve['clear']


@pytest.mark.decision
def test_heldout_loglik_picks_three_patterns_on_box_assembly():
    # The observed wrist alone cannot tell the patterns from one broad Gaussian (they differ in
    # the robot's posture); both agents at a calibrated within-pattern floor can.
    demos = subsampled([g.to_demonstration() for g in generate('box_assembly', 0)], subsample=3)
    cal = heldout_loglik(demos, [1, 2, 3, 4], n_basis=10)
    curve = selection_curve(cal['scores'], higher_is_better=True, paired=True)
    assert [1, 2, 3, 4][curve['index']] == 3 and curve['clear']
    assert len(cal['prior_scale']) == 4 and set(cal['prior_scale']) <= set(PRIOR_SCALES)


def test_calibrated_curve_is_each_k_at_its_best_floor():
    demos = mixture_demos(seed=5, n_obs=1, n_ctrl=1)[0][::2]
    scales = (1.0, 0.01)
    cal = heldout_loglik(demos, [1, 3], scales, n_basis=6)
    for a, K in enumerate([1, 3]):
        curves = [heldout_loglik(demos, [K], [s], n_basis=6)['scores'][0]
                  for s in scales]
        best = int(np.argmax([c.mean() for c in curves]))
        assert cal['prior_scale'][a] == scales[best]
        assert np.allclose(cal['scores'][a], curves[best])
        assert np.allclose(cal['mean_by_scale'][:, a], [c.mean() for c in curves])
    with pytest.raises(ValueError, match='prior_scales must be positive'):
        heldout_loglik(demos, [1], (0.1, -1.0), n_basis=6)


def test_score_demonstrations_is_the_dense_marginal_likelihood_of_both_agents():
    demos = mixture_demos(seed=12, n_obs=2, n_ctrl=1, n_basis=6)[0]
    model = MixtureIProMP(3, n_basis=6).fit(demos)
    d = demos[0]
    idx = np.arange(0, d.t.size, 7)
    t = d.t[idx] * d.duration / d.t[idx][-1]            # keep t[-1] = T: same phase and alpha
    Y = np.hstack([d.observed, d.controlled])[idx]
    Y[3, 0] = Y[3, 1] = np.nan                          # a missing observed sample is skipped
    held = Demonstration(t, Y[:, :2], Y[:, 2:])
    z = t / t[-1]
    A = np.kron(np.eye(3), GaussianBasis(6)(z))         # eq. 19 for all DOFs, DOF-major
    y = Y.T.ravel()
    ok = ~np.isnan(y)
    terms = []
    for k in range(3):
        S = np.diag(np.repeat(model.noise_var_, len(t))) + A @ model.covariances_[k] @ A.T
        lp = multivariate_normal(A[ok] @ model.means_[k], S[np.ix_(ok, ok)]).logpdf(y[ok])
        lp += norm(model.alpha_mean_[k], model.alpha_std_[k]).logpdf(1.0 / t[-1])
        terms.append(np.log(model.weights_[k]) + lp)
    assert model.score_demonstrations([held])[0] == pytest.approx(logsumexp(terms), rel=1e-9)


def test_covariance_floor_is_a_fraction_of_the_within_component_variance():
    demos, labels, _, _ = mixture_demos(seed=13, n_obs=1, n_ctrl=1, n_basis=6)
    model = MixtureIProMP(3, n_basis=6, prior_scale=0.5).fit(demos, labels=labels)
    W = model.demonstration_weights(demos)
    E = W - np.array([W[labels == k].mean(axis=0) for k in range(3)])[labels]
    within = E.T @ E / len(W)                          # pooled within-class covariance
    assert np.allclose(model.prior_cov_, within + 0.5 * np.diag(np.diag(within)))
    # the spread between the classes is no part of it
    assert np.all(np.diag(model.prior_cov_) < 1.5 * W.var(axis=0))


@pytest.mark.decision
def test_leave_one_out_finds_the_sampled_number_of_components_and_needs_a_controlled_agent():
    demos = mixture_demos(seed=5, n_obs=2, n_ctrl=3)[0][::2]
    rms = loo_rms_by_components(demos, [1, 2, 3, 4], n_basis=8)
    assert [1, 2, 3, 4][selection_curve(rms)['index']] == 3
    with pytest.raises(ValueError, match='needs a controlled agent'):
        loo_rms_by_components(mixture_demos(seed=5, n_ctrl=0)[0], [1, 2], n_basis=8)


@pytest.mark.decision
def test_one_sampled_component_gives_k1_and_a_flat_curve_is_reported_as_unclear():
    demos = mixture_demos(seed=6, counts=(30,), durations=((1.0, 1.6),), n_ctrl=0)[0]
    model, info = train(demos, candidates=(1, 2, 3), n_basis=8)
    sel = info['selection']
    assert sel['criterion'] == 'patterns' and sel['chosen'] == 1
    assert sel['candidates'] == [1, 2, 3] and model.n_components == 1
    rng = np.random.default_rng(0)
    flat = rng.normal(size=(4, 40)) + 100 * rng.normal(size=40)     # per-demo level, no K effect
    curve = selection_curve(flat, higher_is_better=True, paired=True)
    assert not curve['clear'] and 'no clear optimum' in curve['note']


def test_tied_and_per_component_noise_equal_the_pooled_residuals():
    demos, labels, basis, _ = mixture_demos(seed=7, n_obs=2, n_ctrl=1)
    model = MixtureIProMP(3, n_basis=8).fit(demos)
    per = MixtureIProMP(3, n_basis=8, noise='per_component').fit(demos)
    sq, m = [], []
    curvature = np.diff(np.eye(8), 2, axis=0)
    for d in demos:       # the penalised eq. 14 by a dense solve per DOF, then residuals
        A = GaussianBasis(8)(d.phase)
        Y = np.hstack([d.observed, d.controlled])
        w = np.column_stack([np.linalg.solve(
            A.T @ A + lam * curvature.T @ curvature + 1e-6 * np.eye(8), A.T @ y)
            for lam, y in zip(model.smoothing_, Y.T)])
        sq.append(((Y - A @ w) ** 2).sum(axis=0))
        m.append(np.full(3, len(d.t)))
    sq, m = np.array(sq), np.array(m)
    assert np.allclose(model.noise_var_, sq.sum(0) / m.sum(0), rtol=1e-6)
    r = per.resp_
    assert np.allclose(per.noise_var_, (r.T @ sq) / (r.T @ m), rtol=1e-6)
    # Fixed noise: separately fitted models share it exactly.
    shared = [MixtureIProMP(1, n_basis=8, noise_var=model.noise_var_).fit(
        [d for d, lb in zip(demos, labels) if lb == k]) for k in range(3)]
    assert all(np.array_equal(s.noise_var_, model.noise_var_) for s in shared)


def test_supervised_fit_has_one_component_per_class_and_scores_weight_vectors():
    demos, labels, _, _ = mixture_demos(seed=8, n_obs=1, n_ctrl=0)
    names = np.array(['c', 'a', 'b'])[labels]
    model = MixtureIProMP(3, n_basis=8).fit(demos, labels=names)
    assert model.classes_ == ['a', 'b', 'c']
    assert np.allclose(model.weights_, [np.mean(names == c) for c in model.classes_])
    W = model.demonstration_weights(demos)
    resp = gmm_responsibilities(W, model.weights_, model.means_, model.covariances_)[0]
    pred = np.array(model.classes_)[np.argmax(resp, axis=1)]
    assert np.mean(pred == names) == 1.0
    assert np.allclose(resp.sum(axis=1), 1.0)
    log_prob = gmm_log_prob(W, model.weights_, model.means_, model.covariances_)
    assert logsumexp(log_prob, axis=1).shape == (len(demos),)
    with pytest.raises(ValueError, match='one component per class'):
        MixtureIProMP(2, n_basis=8).fit(demos, labels=names)


def test_demonstration_weights_are_the_ones_fit_clusters():
    demos = mixture_demos(seed=9, n_obs=1, n_ctrl=0)[0]
    model = MixtureIProMP(3, n_basis=8).fit(demos)
    A = model.basis_(demos[0].phase)
    curvature = np.diff(np.eye(8), 2, axis=0)
    w = np.linalg.solve(A.T @ A + model.smoothing_[0] * curvature.T @ curvature
                        + 1e-6 * np.eye(8), A.T @ demos[0].observed[:, 0])
    assert np.allclose(model.demonstration_weights(demos[:1])[0], w)
    assert np.allclose(model.demonstration_weights(demos), model.prepare(demos).W)


# ---------------------------------------------------------------- CSV files and the command line

def _write_csvs(folder, demos, layout):
    for i, d in enumerate(demos):
        write_csv_demonstration(folder / f'demo_{i:02d}.csv', d, layout)


@pytest.mark.decision
def test_train_command_on_csv_files_single_agent(tmp_path):
    demos = mixture_demos(seed=10, n_obs=2, n_ctrl=0)[0]
    layout = Layout(('ax', 'ay'), (), ('g',), None)
    _write_csvs(tmp_path / 'csv', demos, layout)
    loaded = load_csv_dataset(tmp_path / 'csv', layout)
    assert all(np.allclose(a.observed, b.observed) and np.allclose(a.t, b.t)
               for a, b in zip(loaded, demos))
    out = tmp_path / 'gesture.npz'
    assert main(['train', '--csv', str(tmp_path / 'csv'), '--observed', 'ax,ay',
                 '--observed-units', 'g', '--out', str(out), '--max-components', '4',
                 '--n-basis', '8']) == 0
    model, meta = load_model(out, observed_names=['ax', 'ay'], controlled_names=[])
    assert meta['observed_units'] == ['g', 'g'] and model.n_controlled_ == 0
    sel = meta['extra']['training']['selection']
    assert sel['criterion'] == 'patterns' and sel['chosen'] == model.n_components == 3
    est = OnlineEstimator(model)
    for t, y in zip(demos[0].t, demos[0].observed):
        est.update(t, y)
    assert est.n_observations + est.n_skipped == len(demos[0].t)


@pytest.mark.decision
def test_train_command_on_csv_files_with_a_controlled_agent(tmp_path, capsys):
    demos = mixture_demos(seed=11, n_obs=3, n_ctrl=2)[0]
    layout = Layout(('x', 'y', 'z'), ('q1', 'q2'))
    _write_csvs(tmp_path / 'csv', demos, layout)
    out = tmp_path / 'm.npz'
    assert main(['train', '--csv', str(tmp_path / 'csv'), '--observed', 'x,y,z',
                 '--controlled', 'q1,q2', '--out', str(out), '--components', '3',
                 '--n-basis', '8', '--json', str(tmp_path / 'summary.json')]) == 0
    summary = json.loads((tmp_path / 'summary.json').read_text())
    assert summary['n_components'] == 3 and 'selection' not in summary
    assert 'K = 3: given (--components)' in capsys.readouterr().out
    model, meta = load_model(out, controlled_names=['q1', 'q2'])
    assert meta['controlled_units'] == ['', '']


@pytest.mark.parametrize('text, message', [
    ('t,x\n0,1\n0.1,2\n', r"a\.csv: no column 'y' \(columns: t, x\)"),
    ('t,x,y\n0,1,1\n0.2,2,2\n0.1,3,3\n', r'a\.csv, line 4: time 0\.1 does not increase'),
    ('t,x,y\n0,1,1\n0.1,,2\n', r'a\.csv, line 3: observed columns x are empty but not the others'),
    ('t,x,y\n0,1,1\n,2,2\n', r"a\.csv, line 3: time column 't' is empty"),
    ('t,x,y\n0,1,1\n0.1,2,abc\n', r"a\.csv, line 3: column 'y' is not a number: 'abc'"),
    ('t,x,y\n0,1,1\n0.1,2\n', r'a\.csv, line 3: 2 cells for 3 columns'),
    ('t,x,y\n0,,\n0.1,,\n', r'a\.csv: no observed sample'),
])
def test_csv_errors_are_one_clear_line(tmp_path, text, message):
    (tmp_path / 'a.csv').write_text(text)
    with pytest.raises(CsvError, match=message) as e:
        load_csv_dataset(tmp_path, Layout(('x', 'y')))
    assert '\n' not in str(e.value)


def test_csv_rows_with_every_observed_cell_empty_are_missing_samples_not_dropped(tmp_path):
    (tmp_path / 'a.csv').write_text('t,x,y\n1.0,1,1\n1.1,,\n1.2,3,3\n')
    (d,) = load_csv_dataset(tmp_path, Layout(('x', 'y')))
    assert np.allclose(d.t, [0, 0.1, 0.2]) and np.isnan(d.observed[1]).all()


def test_train_command_reports_a_bad_csv_in_one_line(tmp_path, capsys):
    (tmp_path / 'csv').mkdir()
    (tmp_path / 'csv' / 'a.csv').write_text('t,x\n0,1\n0.1,2\n')
    assert main(['train', '--csv', str(tmp_path / 'csv'), '--observed', 'x,y', '--out',
                 str(tmp_path / 'm.npz')]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith('mixture-ip train: error:') and "no column 'y'" in err
    assert len(err.splitlines()) == 1


def test_training_reports_one_progress_count_over_its_fits():
    """The thesis's criterion: the floors of every K on the folds, then leave-one-out, one
    count; the pattern criterion: the chosen K's floor on the folds."""
    demos = mixture_demos(seed=14, counts=(5, 5), durations=((1.0, 1.2), (1.4, 1.6)),
                          n_obs=1, n_ctrl=1, n_basis=6)[0]
    for criterion, n_fits in (('loo', 2 * 2 * 5 + 2 * len(demos)), ('patterns', 2 * 5)):
        calls = []
        model, info = train(demos, candidates=(1, 2), prior_scales=(1.0, 0.1), n_basis=6,
                            criterion=criterion,
                            progress=lambda done, total, K: calls.append((done, total)))
        assert [d for d, _ in calls] == list(range(1, n_fits + 1)), criterion
        assert {t for _, t in calls} == {n_fits}
        sel = info['selection']
        assert model.prior_scale == sel['prior_scale'] == info['prior_scale']
