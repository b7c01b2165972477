"""Model files: round trip without pickle, and refusal of corrupt or mismatched files."""

import copy
import json
import zipfile

import numpy as np
import pytest

from mixture_ip_ros.core.mixture import MixtureIProMP
from mixture_ip_ros.io.model_file import ModelFileError, load_model, save_model

from mixture_ip_ros.scenarios.synthetic import mixture_demos

OBS = ['wrist_x', 'wrist_y', 'wrist_z']
CTRL = [f'iiwa_joint_{i}' for i in range(1, 5)]


@pytest.fixture(scope='module')
def fitted():
    demos = mixture_demos(seed=2)[0]
    return MixtureIProMP(3, n_basis=8).fit(demos), demos


def _arrays(path):
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def _rewrite(path, **changes):
    data = _arrays(path)
    data.update(changes)
    with open(path, 'wb') as f:
        np.savez(f, **data)


def test_round_trip_predicts_identically(tmp_path, fitted):
    model, demos = fitted
    path = save_model(tmp_path / 'm.npz', model, observed_names=OBS, controlled_names=CTRL,
                      component_labels=['a', 'b', 'c'])
    loaded, meta = load_model(path, observed_names=OBS, controlled_names=CTRL)
    assert meta['component_labels'] == ['a', 'b', 'c']
    d = demos[3]
    z = d.t / d.duration
    a = model.predict_controlled(z[-1:], d.observed[-1:], z)
    b = loaded.predict_controlled(z[-1:], d.observed[-1:], z)
    assert np.array_equal(a['position'], b['position'])
    assert all(v.dtype != object for v in _arrays(path).values())


@pytest.mark.parametrize('change, message', [
    (lambda p: p.write_bytes(b'not a zip'), 'not a model file: not an .npz archive'),
    (lambda p: p.write_text('model = 42\n'), 'not a model file: not an .npz archive'),
    (lambda p: p.write_bytes(p.read_bytes()[:200]), 'not an .npz archive'),
    (lambda p: _huge_header(p), 'declares 8000000000000 bytes of data but holds'),
    (lambda p: _pickled(p), 'holds Python objects'),
    (lambda p: _rewrite(p, means=np.full((3, 56), np.nan)), 'NaN'),
    (lambda p: _rewrite(p, weights=np.array([0.5, 0.6, -0.1])), 'probability'),
    (lambda p: _rewrite(p, means=np.zeros((3, 10))), 'shape'),
    (lambda p: _rewrite(p, covariances=-np.tile(np.eye(56), (3, 1, 1))), 'positive definite'),
])
def test_corrupt_files_are_refused(tmp_path, fitted, change, message):
    path = save_model(tmp_path / 'm.npz', fitted[0], observed_names=OBS, controlled_names=CTRL)
    change(path)
    with pytest.raises(ModelFileError, match=message):
        load_model(path)


def test_the_speed_weight_round_trips_and_a_bad_one_is_refused(tmp_path, fitted):
    model, _ = fitted
    model = copy.copy(model)
    model.speed_weight = 0.2
    path = save_model(tmp_path / 'm.npz', model, observed_names=OBS, controlled_names=CTRL)
    assert load_model(path)[0].speed_weight == 0.2
    for bad in (1.5, -0.1, 'half'):
        model.speed_weight = bad
        with pytest.raises(ValueError, match='speed_weight'):       # not written
            save_model(tmp_path / 'bad.npz', model, observed_names=OBS, controlled_names=CTRL)
        meta = json.loads(str(_arrays(path)['metadata']))
        meta['params']['speed_weight'] = bad
        _rewrite(path, metadata=np.array(json.dumps(meta)))
        with pytest.raises(ModelFileError, match='invalid parameters.*speed_weight'):
            load_model(path)
    # a file written before the weight existed: eq. 16 as it was
    del meta['params']['speed_weight']
    _rewrite(path, metadata=np.array(json.dumps(meta)))
    assert load_model(path)[0].speed_weight == 1.0


def test_version_and_name_mismatch_are_refused(tmp_path, fitted):
    path = save_model(tmp_path / 'm.npz', fitted[0], observed_names=OBS, controlled_names=CTRL)
    with pytest.raises(ModelFileError, match='controlled_names'):
        load_model(path, controlled_names=[f'panda_joint{i}' for i in range(1, 5)])
    meta = json.loads(str(_arrays(path)['metadata']))
    meta['format_version'] = 99
    _rewrite(path, metadata=np.array(json.dumps(meta)))
    with pytest.raises(ModelFileError, match='version 99'):
        load_model(path)
    with pytest.raises(ModelFileError, match='does not exist'):
        load_model(tmp_path / 'nope.npz')


def test_a_pickled_array_is_refused(tmp_path, fitted):
    path = save_model(tmp_path / 'm.npz', fitted[0], observed_names=OBS, controlled_names=CTRL)
    data = _arrays(path)
    data['weights'] = np.array([object()], dtype=object)
    with open(path, 'wb') as f:
        np.savez(f, **data)
    assert zipfile.is_zipfile(path)
    with pytest.raises(ModelFileError, match='weights.npy: holds Python objects'):
        load_model(path)


def test_per_component_noise_units_and_classes_round_trip(tmp_path):
    from mixture_ip_ros.core.demonstration import Layout
    from mixture_ip_ros.io.model_file import model_layout
    demos, labels, _, _ = mixture_demos(seed=4, n_obs=1, n_ctrl=2)
    model = MixtureIProMP(3, n_basis=8, noise='per_component', observation_noise=[0.002]).fit(
        demos, labels=np.array(['x', 'y', 'z'])[labels])
    layout = Layout(('accel_z',), ('a', 'b'), ('g',), ('rad', 'rad'))
    path = save_model(tmp_path / 'm.npz', model, layout=layout, observed_frame='')
    loaded, meta = load_model(path)
    assert model_layout(meta) == layout and loaded.classes_ == ['x', 'y', 'z']
    assert loaded.noise_var_.shape == (3, 3) and np.array_equal(loaded.noise_var_, model.noise_var_)
    d = demos[0]
    assert np.array_equal(loaded.component_posterior(d.phase, d.observed),
                          model.component_posterior(d.phase, d.observed))


def test_a_format_1_file_loads_with_metre_and_radian_units(tmp_path, fitted):
    path = save_model(tmp_path / 'm.npz', fitted[0], observed_names=OBS, controlled_names=CTRL)
    meta = json.loads(str(_arrays(path)['metadata']))
    meta['format_version'] = 1
    del meta['observed_units'], meta['controlled_units']
    meta['params'] = {k: v for k, v in meta['params'].items() if k not in ('noise', 'noise_var')}
    meta['params']['min_alpha_rel_std'] = 0.05        # a parameter format 1 had
    meta['params']['observation_noise'] = 0.01
    _rewrite(path, metadata=np.array(json.dumps(meta)))
    model, meta = load_model(path, observed_names=OBS, controlled_names=CTRL)
    assert meta['observed_units'] == ['m'] * 3 and meta['controlled_units'] == ['rad'] * 4
    assert model.observation_noise == 0.01 and model.noise == 'tied'


def _huge_header(path):
    """An .npz whose array header declares 1e12 floats (a corrupt or hostile file)."""
    import io
    import zipfile
    b = io.BytesIO()
    np.lib.format.write_array_header_1_0(b, {'descr': '<f8', 'fortran_order': False,
                                            'shape': (10**12,)})
    with zipfile.ZipFile(path, 'w') as z:
        z.writestr('weights.npy', b.getvalue() + bytes(64))


def _pickled(path):
    import io
    import zipfile
    b = io.BytesIO()
    np.save(b, np.array([{'a': 1}], dtype=object), allow_pickle=True)
    with zipfile.ZipFile(path, 'w') as z:
        z.writestr('weights.npy', b.getvalue())


def test_a_failed_save_leaves_the_previous_model_whole(tmp_path, fitted, monkeypatch):
    path = save_model(tmp_path / 'm.npz', fitted[0], observed_names=OBS, controlled_names=CTRL)
    before = path.read_bytes()

    def disk_full(f, **arrays):
        f.write(b'PK\x03\x04 half a model')
        raise OSError(28, 'No space left on device')
    monkeypatch.setattr(np, 'savez', disk_full)
    with pytest.raises(OSError, match='No space left'):
        save_model(path, fitted[0], observed_names=OBS, controlled_names=CTRL)
    assert path.read_bytes() == before
    assert [f.name for f in tmp_path.iterdir()] == ['m.npz']         # no temporary left
    load_model(path)


def test_the_phase_warps_round_trip_and_a_file_without_them_keeps_the_linear_phase(tmp_path,
                                                                                     fitted):
    from mixture_ip_ros.core.warp import N_WARP
    from mixture_ip_ros.core.warped import PhaseWarps
    model, demos = fitted
    named = [copy.copy(d) for d in demos]
    named[4].name = 'rec4'
    warped = copy.copy(model)
    warped.warps_ = PhaseWarps().fit(model, named)
    warped.warps_.failed_ = ['rec4']               # as training names a fit that failed
    path = save_model(tmp_path / 'w.npz', warped, observed_names=OBS, controlled_names=CTRL)
    loaded, meta = load_model(path)
    assert np.array_equal(loaded.warps_.mean_, warped.warps_.mean_)
    assert np.array_equal(loaded.warps_.sd_, warped.warps_.sd_)
    assert loaded.warps_.failed_ == ['rec4'] and meta['warp_failed'] == ['rec4']
    d = demos[1]
    assert np.array_equal(loaded.warps_.component_posterior(loaded, d.phase, d.observed)[0],
                          warped.warps_.component_posterior(warped, d.phase, d.observed)[0])
    plain = save_model(tmp_path / 'p.npz', model, observed_names=OBS, controlled_names=CTRL)
    linear = load_model(plain)[0]
    assert linear.warps_ is None
    assert 'warp_mean' not in _arrays(plain)
    for bad, message in ((dict(warp_sd=np.zeros((3, N_WARP))), 'positive warp_sd'),
                         (dict(warp_mean=np.zeros((2, N_WARP))), 'shape'),
                         (dict(warp_mean=np.full((3, N_WARP), np.nan)), 'finite warp_mean')):
        _rewrite(path, **bad)
        with pytest.raises(ModelFileError, match=message):
            load_model(path)
        save_model(path, warped, observed_names=OBS, controlled_names=CTRL)
    meta = json.loads(str(_arrays(path)['metadata']))
    for key, value, message in (('warp', {'log_rate_bumps': 7, 'bump_width': 0.2},
                                 'another family'),
                                ('warp_failed', 'rec4', 'warp_failed must list')):
        _rewrite(path, metadata=np.array(json.dumps({**meta, key: value})))
        with pytest.raises(ModelFileError, match=message):
            load_model(path)
    save_model(path, warped, observed_names=OBS, controlled_names=CTRL)
    data = _arrays(path)
    del data['warp_sd']
    with open(path, 'wb') as f:
        np.savez(f, **data)
    with pytest.raises(ModelFileError, match='warp_mean and warp_sd go together'):
        load_model(path)
