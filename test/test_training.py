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
