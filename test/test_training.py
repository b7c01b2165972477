"""Training: K by leave-one-out, the final fit with the method asked for."""

import numpy as np

from mixture_ip_ros.core.demonstration import Demonstration
from mixture_ip_ros.app.training import train

from mixture_ip_ros.scenarios.synthetic import mixture_demos


def test_em_training_chooses_k_on_regression_fits_and_fits_the_model_by_em():
    demos, labels, _, _ = mixture_demos(seed=0)
    gappy = []
    for i, d in enumerate(demos):       # a gap of 20 % of every demonstration, at varying places
        obs, ctrl = d.observed.copy(), d.controlled.copy()
        n = len(d.t)
        lo = (i * 7) % (n - n // 5)
        obs[lo:lo + n // 5] = np.nan
        ctrl[lo:lo + n // 5] = np.nan
        gappy.append(Demonstration(d.t, obs, ctrl, label=d.label))
    model, info = train(gappy, candidates=range(1, 6), method='em', n_basis=8)
    assert info['loo_method'] == 'regression' and info['n_components'] == 3
    assert model.method == 'em' and model.n_iter_ > 2
    assert np.all(np.diff(model.log_likelihood_) >= -1e-8 * np.abs(model.log_likelihood_[1:]))
    # every pattern in a component of its own
    comp = model.resp_.argmax(axis=1)
    assert all(len(set(comp[labels == k])) == 1 for k in range(3))
    assert len(set(comp)) == 3


def test_leave_one_out_floor_is_the_one_its_own_criterion_prefers():
    """The covariance floor of the leave-one-out curve (and of the model) is the one that
    predicts the controlled agent best on the held-out folds, not the held-out likelihood's."""
    demos = mixture_demos(seed=0)[0]
    model, info = train(demos, candidates=range(1, 5), n_basis=8)
    sel = info['selection']
    from mixture_ip_ros.core.mixture import calibrated_heldout_curves, loo_rms_by_components
    curves = calibrated_heldout_curves(demos, [1, 2, 3, 4], (), n_basis=8, method='regression')
    assert sel['loo_rms']['prior_scale'] == curves['controlled_rms']['prior_scale']
    assert sel['heldout_loglik']['prior_scale'] == curves['loglik']['prior_scale']
    K = info['n_components']
    assert model.prior_scale == sel['prior_scale'] == curves['controlled_rms']['prior_scale'][K - 1]
    rms = loo_rms_by_components(demos, [K], n_basis=8, method='regression',
                                prior_scale=model.prior_scale)
    assert np.allclose(sel['loo_rms']['mean'][K - 1], rms.mean(), rtol=1e-12)
    # Leave-one-out trains on more demonstrations than a held-out fold: a K only it can fit
    # takes the floor of the largest K the folds calibrated.
    few = demos[::4]
    _, info = train(few, candidates=range(1, len(few)), n_basis=8)
    held = info['selection']['heldout_loglik']['candidates']
    loo = info['selection']['loo_rms']
    assert loo['candidates'][-1] > held[-1]
    assert loo['prior_scale'][len(held):] == [loo['prior_scale'][len(held) - 1]] * (
        len(loo['candidates']) - len(held))
