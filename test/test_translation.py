"""Where an interaction happened, as a variable of its own (``translation``): the patterns do
not see it, the model carries it exactly as N(mu_k + B m, Sigma_k + B S B^T), and conditioning
on the observed agent infers it and moves the controlled agent by it."""

import numpy as np
import pytest

from mixture_ip_ros.core.basis import GaussianBasis
from mixture_ip_ros.core.demonstration import Demonstration
from mixture_ip_ros.core.mixture import MixtureIProMP
from mixture_ip_ros.core.pattern_space import PatternSpace
from mixture_ip_ros.core.patterns import offset_operators, translation_for, without_offsets
from mixture_ip_ros.scenarios.synthetic import mixture_demos

GROUPS = ((0, 3), (1, 4), (2, 5))


def _moved(demos, rng, std=0.3):
    out, offsets = [], []
    for d in demos:
        o = rng.standard_normal(3) * std
        out.append(Demonstration(d.t, d.observed + o, d.controlled + o, d.label, d.name))
        offsets.append(o)
    return out, np.array(offsets)


def test_the_offset_is_each_groups_mean_position_over_the_phase():
    """o = T w: the mean over the group's DOFs of each path's mean over z in [0, 1] (a
    quadrature of the path itself, the oracle); B o moves the paths by o; T B = I."""
    N, basis = 8, GaussianBasis(8)
    rng = np.random.default_rng(0)
    W = rng.standard_normal((5, 6 * N))
    T, B = offset_operators(N, 6, GROUPS)
    z = np.linspace(0, 1, 20001)
    paths = np.einsum('zn,idn->idz', basis(z), W.reshape(5, 6, N))
    mean_path = np.trapezoid(paths, z, axis=2)                             # (5, 6)
    for a, g in enumerate(GROUPS):
        assert np.allclose(W @ T[a], mean_path[:, list(g)].mean(axis=1), atol=1e-8)
    assert np.allclose(T @ B, np.eye(3))
    moved = W + np.array([0.1, -0.2, 0.3]) @ B.T
    assert np.allclose(np.einsum('zn,idn->idz', basis(z), moved.reshape(5, 6, N))
                       - paths, np.repeat(np.array([0.1, -0.2, 0.3, 0.1, -0.2, 0.3])[None, :, None],
                                          5, 0), atol=1e-12)
    assert np.allclose(without_offsets(moved, N, GROUPS), without_offsets(W, N, GROUPS))


def test_the_pattern_coordinates_do_not_see_where_the_pair_stood():
    demos = mixture_demos(seed=1, n_obs=3, n_ctrl=3)[0]
    moved, _ = _moved(demos, np.random.default_rng(1))
    a = MixtureIProMP(1, n_basis=8).prepare(demos)
    b = MixtureIProMP(1, n_basis=8, smoothing=a.smoothing).prepare(moved)
    X = PatternSpace(8, 3, translation=GROUPS).fit_transform(a.W)
    assert np.allclose(PatternSpace(8, 3, translation=GROUPS).fit_transform(b.W), X, atol=1e-9)
    unmoved, moved = PatternSpace(8, 3), PatternSpace(8, 3)
    unmoved.fit_transform(a.W), moved.fit_transform(b.W)
    assert not np.allclose(moved.distances_, unmoved.distances_, atol=1e-3)


def test_the_mixture_finds_the_same_patterns_wherever_each_pair_stood():
    demos, labels, _, _ = mixture_demos(seed=1, n_obs=3, n_ctrl=3)
    moved, offsets = _moved(demos, np.random.default_rng(2))
    smoothing = MixtureIProMP(1, n_basis=8).prepare(demos).smoothing
    here = MixtureIProMP(3, n_basis=8, translation=GROUPS, smoothing=smoothing).fit(demos)
    there = MixtureIProMP(3, n_basis=8, translation=GROUPS, smoothing=smoothing).fit(moved)
    assert np.allclose(here.resp_, there.resp_, atol=1e-8)
    # The components differ by where the pairs stood on average, along B only, and by the
    # offsets' covariance, B S B^T, with S their sample covariance (plus its tiny floor).
    _, B = offset_operators(8, 6, GROUPS)
    shift = there.offset_mean_ - here.offset_mean_
    assert np.allclose(there.means_ - here.means_, (B @ shift)[None], atol=1e-8)
    assert np.allclose(there.covariances_ - here.covariances_,
                       (B @ (there.offset_cov_ - here.offset_cov_) @ B.T)[None], atol=1e-8)
    # The moved pairs' offsets are the known ones plus each recording's own mean position.
    assert np.allclose(there.offset_mean_ - here.offset_mean_, offsets.mean(axis=0), atol=1e-8)
    assert np.all(np.linalg.eigvalsh(there.offset_cov_) > 0)


def test_conditioning_on_the_observed_agent_moves_the_controlled_agent_with_it():
    """The same held-out interaction 40 cm away: its partner predicted from the observed
    agent's whole path moves by the same 40 cm (to within the spread of the pattern's own
    mean positions, which the offset estimate cannot tell from a shift)."""
    demos = mixture_demos(seed=1, n_obs=3, n_ctrl=3)[0]
    moved, _ = _moved(demos, np.random.default_rng(3))
    model = MixtureIProMP(3, n_basis=8, translation=GROUPS).fit(moved[1:])
    test = demos[0]
    o = np.array([0.4, -0.25, 0.1])
    z = test.phase
    at_home = model.predict_controlled(z, test.observed, z)['position']
    away = model.predict_controlled(z, test.observed + o, z)['position']
    assert np.allclose(away - at_home, o, atol=0.05 * np.linalg.norm(o))
    # A mixture without the offset variable learns some of it from its members' spread (the
    # offsets are most of it), less exactly.
    plain = MixtureIProMP(3, n_basis=8).fit(moved[1:])
    plain_shift = (plain.predict_controlled(z, test.observed + o, z)['position']
                   - plain.predict_controlled(z, test.observed, z)['position'])
    assert (np.abs(away - at_home - o).max()
            < 0.5 * np.abs(plain_shift - o).max())


def test_translation_modes_name_their_groups_and_refuse_what_they_cannot_mean():
    assert translation_for('none', 3, 3) == ()
    assert translation_for('shared', 3, 3) == GROUPS
    assert translation_for('observed', 2, 0) == ((0,), (1,))
    with pytest.raises(ValueError, match='as many of each'):
        translation_for('shared', 3, 7)
    with pytest.raises(ValueError, match='single agent'):
        translation_for('observed', 3, 7)
    with pytest.raises(ValueError, match='one of'):
        translation_for('room', 3, 3)
    with pytest.raises(ValueError, match='disjoint'):
        MixtureIProMP(1, translation=((0, 1), (1, 2)))._check_params()
    with pytest.raises(ValueError, match="method='regression'"):
        MixtureIProMP(1, method='em', translation=GROUPS)._check_params()
    demos = mixture_demos(seed=1, n_obs=1, n_ctrl=1, counts=(3, 3, 3))[0]
    with pytest.raises(ValueError, match='0..1'):
        MixtureIProMP(1, n_basis=8, translation=((0, 5),)).fit(demos)


def test_a_model_file_whose_groups_name_dofs_it_has_not_is_refused(tmp_path):
    import json
    from mixture_ip_ros.io.model_file import ModelFileError, load_model, save_model
    demos = mixture_demos(seed=1, n_obs=3, n_ctrl=3, counts=(4, 4, 4))[0]
    model = MixtureIProMP(2, n_basis=8, translation=np.array(GROUPS)).fit(demos)
    path = tmp_path / 'm.npz'
    save_model(path, model, observed_names=['x', 'y', 'z'], controlled_names=['a', 'b', 'c'])
    loaded, meta = load_model(path)
    assert loaded.translation == GROUPS and meta['params']['translation'] == [[0, 3], [1, 4],
                                                                              [2, 5]]
    with np.load(path) as npz:
        arrays = {k: npz[k] for k in npz.files}
    meta['params']['translation'] = [[0, 9]]
    arrays['metadata'] = np.array(json.dumps(meta))
    np.savez(tmp_path / 'bad.npz', **arrays)
    with pytest.raises(ModelFileError, match='invalid parameters'):
        load_model(tmp_path / 'bad.npz')


def test_em_with_translation_is_refused_before_training(tmp_path, capsys):
    from mixture_ip_ros.app.cli import main
    (tmp_path / 'csv').mkdir()
    with pytest.raises(SystemExit) as exit_:
        main(['train', '--csv', str(tmp_path / 'csv'), '--observed', 'x,y,z', '--controlled',
              'a,b,c', '--translation', 'shared', '--method', 'em', '--out',
              str(tmp_path / 'm.npz')])
    assert exit_.value.code == 2 and 'with --method regression only' in capsys.readouterr().err
