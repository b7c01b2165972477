"""Options of the evaluations and of training: the share of each fold's training recordings
kept per label (app.evaluation.interactions.kept_share), `--translation` on the command line
(checked before any data is read; a trained model records its groups and fitted offsets), and
model files from before the smoothing and the offsets still loading."""

import json

import numpy as np
import pytest

from mixture_ip_ros.app.cli import main
from mixture_ip_ros.app.evaluation.interactions import kept_share
from mixture_ip_ros.core.demonstration import Layout
from mixture_ip_ros.io.csv_files import write_csv_demonstration
from mixture_ip_ros.io.model_file import load_model
from mixture_ip_ros.scenarios.synthetic import mixture_demos

from test_cli import _exits_2_in_one_line_and_creates_nothing

SHARED = [[0, 3], [1, 4], [2, 5]]


def _groups(groups):
    """Translation groups as a list of lists, however they are held (tuples or lists)."""
    return [[int(j) for j in g] for g in (groups or ())]


# -- kept_share -----------------------------------------------------------------------------
def _labelled():
    """40 recordings of 4 labels of 4, 6, 10 and 20 members, interleaved."""
    labels = np.array(['a'] * 4 + ['b'] * 6 + ['c'] * 10 + ['d'] * 20)
    return np.random.default_rng(0).permutation(labels)


@pytest.mark.parametrize('fraction, expected', [
    (0.5, {'a': 2, 'b': 3, 'c': 5, 'd': 10}),
    (0.7, {'a': 3, 'b': 4, 'c': 7, 'd': 14}),       # round(2.8), round(4.2), 7, 14
    (0.1, {'a': 2, 'b': 2, 'c': 2, 'd': 2}),        # round(0.4 .. 2) < 2: at least two
    (1.0, {'a': 4, 'b': 6, 'c': 10, 'd': 20}),
])
def test_kept_share_keeps_the_rounded_share_of_every_label_at_least_two(fraction, expected):
    labels = _labelled()
    rows = np.arange(len(labels))
    kept = kept_share(rows, labels, fraction, seed=3)
    assert {k: int(np.sum(labels[kept] == k)) for k in 'abcd'} == expected
    assert np.all(np.diff(kept) > 0) and set(kept) <= set(rows)


def test_kept_share_draws_only_from_the_given_rows_and_counts_their_labels_only():
    """A fold's training rows (every other row): the share is of each label's members among
    them, and nothing outside them is kept."""
    labels = _labelled()
    rows = np.arange(0, len(labels), 2)
    kept = kept_share(rows, labels, 0.5, seed=1)
    assert set(kept.tolist()) <= set(rows.tolist())
    for k in 'abcd':
        n = int(np.sum(labels[rows] == k))
        assert np.sum(labels[kept] == k) == min(n, max(2, int(round(0.5 * n))))
    assert np.array_equal(kept, np.sort(kept))


def test_kept_share_keeps_a_label_with_fewer_than_two_members_whole():
    labels = np.array(['a', 'b', 'b', 'b', 'b', 'b', 'b'])
    kept = kept_share(np.arange(7), labels, 0.5, seed=0)
    assert 0 in kept and np.sum(labels[kept] == 'b') == 3


def test_kept_share_is_deterministic_per_seed_and_differs_between_seeds():
    labels = _labelled()
    rows = np.arange(len(labels))
    a = kept_share(rows, labels, 0.5, seed=7)
    assert np.array_equal(a, kept_share(rows, labels, 0.5, seed=7))
    draws = {tuple(kept_share(rows, labels, 0.5, seed=s)) for s in range(5)}
    assert len(draws) == 5


def test_kept_share_over_many_seeds_keeps_every_member_equally_often():
    """Uniform draws without replacement: each of label d's 20 members is kept with
    probability 10 / 20 in each of 400 seeds; a count has standard error sqrt(400 / 4) = 10,
    and every count is asserted within 4.5 of them (20 counts, so no false alarm in
    practice)."""
    labels = _labelled()
    rows = np.arange(len(labels))
    counts = np.zeros(len(labels))
    for s in range(400):
        counts[kept_share(rows, labels, 0.5, seed=s)] += 1
    d = labels == 'd'
    assert np.all(np.abs(counts[d] - 200) < 45), counts[d]


@pytest.mark.parametrize('fraction', [0.0, -0.1, 1.01, float('nan')])
def test_kept_share_refuses_a_fraction_outside_zero_to_one(fraction):
    labels = _labelled()
    with pytest.raises(ValueError, match='train_fraction must be in'):
        kept_share(np.arange(len(labels)), labels, fraction, seed=0)


# -- --translation on the command line ------------------------------------------------------
def _inputs(tmp):
    (tmp / 'csv').mkdir()
    (tmp / 'csv' / 'a.csv').write_text('t,x,y,z,hx,hy,hz\n0,1,2,3,4,5,6\n0.1,2,3,4,5,6,7\n')
    (tmp / 'labels.json').write_text('{"a": "reach"}')


TRAIN = ['train', '--csv', '{tmp}/csv', '--out', '{tmp}/m.npz']
EVALUATE = ['evaluate', '--csv', '{tmp}/csv', '--labels', '{tmp}/labels.json', '--out',
            '{tmp}/eval']
HANDS = ['--observed', 'x,y,z', '--controlled', 'hx,hy,hz']


@pytest.mark.parametrize('argv, message', [
    (['train', '{tmp}', '--out', '{tmp}/m.npz', '--translation', 'shared'],
     '--translation: for --csv DIR only'),
    (['evaluate', '--scenario', 'interactions', '--out', '{tmp}/eval', '--translation',
      'shared'], '--translation: for --csv DIR only'),
    (TRAIN + ['--observed', 'x,y,z', '--controlled', 'hx,hy', '--translation', 'shared'],
     "translation 'shared' pairs observed DOF i with controlled DOF i: it needs as many of "
     'each, got 3 and 2'),
    (EVALUATE + ['--observed', 'x,y,z', '--controlled', 'hx,hy', '--translation', 'shared'],
     'it needs as many of each, got 3 and 2'),
    (TRAIN + HANDS + ['--observed-units', 'm', '--controlled-units', 'rad', '--translation',
                      'shared'],
     "--translation shared: x and hx move together but have units ['m', 'rad']"),
    (EVALUATE + HANDS + ['--observed-units', 'm', '--controlled-units', 'm,m,rad',
                         '--translation', 'shared'],
     "--translation shared: z and hz move together but have units ['m', 'rad']"),
    (TRAIN + HANDS + ['--translation', 'observed'],
     "translation 'observed' is for a single agent"),
    (EVALUATE + HANDS + ['--translation', 'observed'],
     "translation 'observed' is for a single agent"),
    (TRAIN + ['--observed', 'x', '--translation', 'both'],
     "argument --translation: invalid choice: 'both'"),
])
def test_a_translation_that_cannot_apply_fails_in_one_line_with_exit_2_before_any_data(
        tmp_path, capsys, nothing_runs, argv, message):
    _inputs(tmp_path)
    _exits_2_in_one_line_and_creates_nothing(tmp_path, capsys, argv, message)


@pytest.mark.parametrize('extra, groups', [
    (HANDS + ['--translation', 'shared'], SHARED),
    (HANDS + ['--observed-units', 'm', '--controlled-units', 'm', '--translation', 'shared'],
     SHARED),
    (['--observed', 'x,y,z', '--translation', 'observed'], [[0], [1], [2]]),
    (HANDS, []),
])
def test_a_translation_that_applies_reaches_training_and_the_evaluation_as_groups(
        tmp_path, capsys, monkeypatch, extra, groups):
    import mixture_ip_ros.app.evaluation as evaluation
    import mixture_ip_ros.app.training as training
    calls = []
    monkeypatch.setattr(training, 'train_to_file',
                        lambda demos, out, **kwargs: calls.append(kwargs) or (None, {}))
    monkeypatch.setattr(evaluation, 'evaluate_csv',
                        lambda *args, **kwargs: calls.append(kwargs) or {})
    _inputs(tmp_path)
    for argv in (TRAIN, EVALUATE):
        assert main([a.format(tmp=tmp_path) for a in argv] + extra) == 0
    assert [_groups(c['translation']) for c in calls] == [groups, groups]


# -- a model trained with --translation shared, and one from before the offsets -------------
@pytest.fixture(scope='module')
def shared_model(tmp_path_factory):
    """`mixture-ip train --csv --translation shared` on 18 synthetic recordings of two 3-D
    hands (3 patterns), K = 3, 8 basis functions: (the model file, the recordings)."""
    tmp = tmp_path_factory.mktemp('shared')
    demos = mixture_demos(seed=1, n_obs=3, n_ctrl=3, counts=(6, 6, 6))[0]
    layout = Layout(('x', 'y', 'z'), ('hx', 'hy', 'hz'), ('m',), ('m',))
    for i, d in enumerate(demos):
        write_csv_demonstration(tmp / 'csv' / f'demo_{i:02d}.csv', d, layout)
    out = tmp / 'm.npz'
    assert main(['train', '--csv', str(tmp / 'csv'), '--observed', 'x,y,z', '--controlled',
                 'hx,hy,hz', '--observed-units', 'm', '--controlled-units', 'm',
                 '--translation', 'shared', '--components', '3', '--n-basis', '8',
                 '--out', str(out)]) == 0
    return out, demos


def _mean_position(d, a):
    """Where recording ``d`` happened on axis ``a``: both hands' mean position over the phase
    (trapezoidal rule on the samples), averaged over the two hands."""
    z = d.phase

    def integral(y):
        return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(z)))
    return 0.5 * (integral(d.observed[:, a]) + integral(d.controlled[:, a]))


def test_a_model_trained_with_shared_translation_records_its_groups_and_fitted_offsets(
        shared_model):
    """The offsets are each recording's mean position over the phase, averaged over a group's
    DOFs (core.patterns.offset_operators), their mean and sample covariance over the
    recordings. Oracle: the same from the samples by the trapezoidal rule. The fit and the
    samples differ by the basis fit's error on smooth paths with 2 mm noise, averaged over
    ~50 samples: tolerances of 0.5 mm on the mean and 3e-4 m^2 on the covariance (offsets
    spread by 15-30 cm: variances 0.02-0.1 m^2)."""
    path, demos = shared_model
    model, meta = load_model(path, observed_names=['x', 'y', 'z'],
                             controlled_names=['hx', 'hy', 'hz'])
    assert meta['params']['translation'] == SHARED
    assert _groups(model.translation) == SHARED
    assert model.offset_mean_.shape == (3,) and model.offset_cov_.shape == (3, 3)
    assert np.array_equal(model.offset_cov_, model.offset_cov_.T)
    assert np.all(np.linalg.eigvalsh(model.offset_cov_) > 0)
    assert model.smoothing_.shape == (6,) and np.all(model.smoothing_ >= 0)
    assert np.allclose(meta['offsets']['mean'], model.offset_mean_)
    assert np.allclose(meta['smoothing'], model.smoothing_)
    O = np.array([[_mean_position(d, a) for a in range(3)] for d in demos])
    assert np.allclose(model.offset_mean_, O.mean(axis=0), rtol=0, atol=5e-4)
    assert np.allclose(model.offset_cov_, np.cov(O, rowvar=False), rtol=0, atol=3e-4)


def _rewrite_as_before_the_offsets(path, out):
    """``path``'s model file as a package before the smoothing and the offsets wrote it: the
    metadata without 'smoothing' and 'offsets', its params without 'translation' and
    'smoothing'; every other array as it was (io.model_file.save_model's layout)."""
    with np.load(path, allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    meta = json.loads(str(arrays.pop('metadata')))
    for key in ('smoothing', 'offsets'):
        del meta[key]
    for key in ('translation', 'smoothing'):
        del meta['params'][key]
    np.savez(out, metadata=np.array(json.dumps(meta)), **arrays)
    return meta


def test_a_model_file_from_before_the_smoothing_and_offsets_still_loads(shared_model,
                                                                        tmp_path):
    from mixture_ip_ros.core.online import OnlineEstimator
    path, demos = shared_model
    old = tmp_path / 'old.npz'
    written = _rewrite_as_before_the_offsets(path, old)
    assert 'offsets' not in written and 'translation' not in written['params']
    model, meta = load_model(old)
    new, _ = load_model(path)
    assert model.smoothing_ is None and not model.translation
    assert getattr(model, 'offset_mean_', None) is None
    assert model.smoothing is None
    for name in ('weights', 'means', 'covariances', 'noise_var', 'prior_cov'):
        assert np.array_equal(getattr(model, name + '_'), getattr(new, name + '_'))
    # The estimator reads the means and covariances (which hold the offsets): it runs.
    est = OnlineEstimator(model)
    for t, y in zip(demos[0].t, demos[0].observed):
        est.update(t, y)
    assert np.isclose(est.component_posterior().sum(), 1.0)
