"""The NuiSI loader: upstream files read without running what their pickles could name, pinned
checksums, downloads that leave nothing behind, and the real recordings where they are cached."""

import os
import pickle
import zipfile

import numpy as np
import pytest

from mixture_ip_ros.io.cache import cache_dir, download_verified, sha256_of
from mixture_ip_ros.io.safe_npz import load_npz
from mixture_ip_ros.scenarios import nuisi


def _object_array(items):
    out = np.empty(len(items), dtype=object)
    out[:] = items
    return out


def _write_nuisi_like(path, n=3, T=20, J=4, seed=0):
    rng = np.random.default_rng(seed)
    data = _object_array([rng.normal(size=(T + i, 6 * J)) for i in range(n)])
    np.savez_compressed(path, train_data=data, train_labels=np.arange(n) % 2,
                        test_data=data[:1], test_labels=np.zeros(1))
    return data


def test_object_arrays_of_numeric_arrays_are_read_as_numpy_writes_them(tmp_path):
    path = tmp_path / 'x.npz'
    data = _write_nuisi_like(path)
    got = load_npz(path)
    assert set(got) == {'train_data', 'train_labels', 'test_data', 'test_labels'}
    assert len(got['train_data']) == 3
    for a, b in zip(got['train_data'], data):
        assert np.array_equal(a, b)
    assert np.array_equal(got['train_labels'], [0, 1, 0])


class _Payload:
    def __reduce__(self):
        return (os.system, ('echo pwned',))


def test_a_pickle_naming_anything_but_numpy_arrays_is_refused_in_one_line(tmp_path):
    path = tmp_path / 'evil.npz'
    # an .npy member whose object array pickles a callable (what allow_pickle=True would run)
    with zipfile.ZipFile(path, 'w') as z:
        buf = pickle.dumps(_object_array([_Payload()]), protocol=3)
        header = {'descr': '|O', 'fortran_order': False, 'shape': (1,)}
        from io import BytesIO
        from numpy.lib import format as npy_format
        f = BytesIO()
        npy_format.write_array_header_1_0(f, header)
        z.writestr('train_data.npy', f.getvalue() + buf)
    with pytest.raises(ValueError) as info:
        load_npz(path)
    message = str(info.value)
    assert 'refused' in message and 'system' in message and '\n' not in message


def test_an_object_array_holding_non_numbers_is_refused(tmp_path):
    path = tmp_path / 'strings.npz'
    np.savez(path, train_data=_object_array([np.array(['a', 'b'])]))
    with pytest.raises(ValueError, match='not a numeric array'):
        load_npz(path)


def test_a_file_that_is_not_an_npz_is_refused(tmp_path):
    path = tmp_path / 'junk.npz'
    path.write_bytes(b'not a zip file')
    with pytest.raises(ValueError, match='not a readable .npz'):
        load_npz(path)


def test_a_cached_file_with_another_checksum_is_refused(tmp_path):
    folder = tmp_path / 'nuisi'
    folder.mkdir()
    _write_nuisi_like(folder / nuisi.VERSIONS['v2'].file)
    with pytest.raises(ValueError, match='is not the pinned'):
        nuisi.recordings('v2', 'train', cache=tmp_path)


def test_a_download_is_kept_only_with_the_pinned_checksum(tmp_path):
    source = tmp_path / 'upstream.npz'
    _write_nuisi_like(source)
    target = tmp_path / 'cache' / 'file.npz'
    with pytest.raises(ValueError, match='is not the pinned'):
        download_verified(source.as_uri(), target, '0' * 64)
    assert not target.exists() and os.listdir(target.parent) == []   # nothing half-kept
    download_verified(source.as_uri(), target, sha256_of(source))
    assert sha256_of(target) == sha256_of(source)
    with pytest.raises(RuntimeError, match='could not download'):
        download_verified((tmp_path / 'missing.npz').as_uri(), tmp_path / 'cache' / 'b.npz',
                          '0' * 64)
    assert os.listdir(target.parent) == ['file.npz']


@pytest.fixture(scope='module')
def cached():
    """The real files, where the user cache has them (./dev seeds it from a local copy)."""
    folder = cache_dir() / 'nuisi'
    for v in nuisi.VERSIONS.values():
        if not (folder / v.file).is_file():
            pytest.skip(f'NuiSI is not in {folder} (./dev seeds it from ../shared/data/nuisi)')


@pytest.mark.parametrize('version, counts', [('v1', (90, 24, 6, 10)), ('v2', (33, 11, 4, 4))])
def test_the_real_recordings_have_the_upstream_splits(cached, version, counts):
    n_train, n_test, n_labels, n_joints = counts
    train, test = nuisi.recordings(version, 'train'), nuisi.recordings(version, 'test')
    assert (len(train), len(test)) == (n_train, n_test)
    assert len({r.label for r in train + test}) == n_labels
    assert all(r.person1.shape == r.person2.shape and r.person1.shape[1:] == (n_joints, 3)
               for r in train + test)
    demos = nuisi.demonstrations(version, 'test')
    assert demos[0].n_observed_dofs == demos[0].n_controlled_dofs == 3
    assert demos[0].t[1] == pytest.approx(1.0 / nuisi.VERSIONS[version].rate)
