"""Reading upstream ``.npz`` files whose object arrays were saved with pickle, without running
what a pickle may name.

numpy stores an object array (for instance a list of recordings of unequal lengths) as a pickle
inside the ``.npy`` member. ``np.load(..., allow_pickle=True)`` would execute any callable that
pickle names; this reader admits only numpy's own array reconstruction (``ndarray``, ``dtype``
and ``_reconstruct``), and every element of an object array must itself be a numeric array. A
file that names anything else, or holds anything else, is refused whole with a ValueError.
"""

import io
import pickle
import zipfile
from pathlib import Path

import numpy as np
from numpy.lib import format as npy_format

# What pickling an ndarray (and its dtype) names, under numpy 1.x and 2.x module paths.
_ALLOWED = {('numpy', 'ndarray'), ('numpy', 'dtype'),
            ('numpy.core.multiarray', '_reconstruct'), ('numpy._core.multiarray', '_reconstruct')}


class _ArraysOnly(pickle.Unpickler):
    def find_class(self, module, name):
        if (module, name) not in _ALLOWED:
            raise pickle.UnpicklingError(f'names {module}.{name}, not a numpy array type')
        return super().find_class(module, name)


def _read_member(raw: bytes, what: str) -> np.ndarray:
    f = io.BytesIO(raw)
    version = npy_format.read_magic(f)
    header = (npy_format.read_array_header_1_0 if version == (1, 0)
              else npy_format.read_array_header_2_0)
    shape, fortran, dtype = header(f)
    if not dtype.hasobject:
        f.seek(0)
        return npy_format.read_array(f, allow_pickle=False)
    try:
        array = _ArraysOnly(f).load()
    except Exception as error:     # any unpickling failure refuses the file
        raise ValueError(f'{what}: refused, its pickle {error}') from None
    if not isinstance(array, np.ndarray) or array.shape != shape:
        raise ValueError(f'{what}: refused, its pickle is not the {shape} array its header says')
    for i, element in enumerate(array.ravel()):
        if not (isinstance(element, np.ndarray) and element.dtype.kind in 'biuf'):
            raise ValueError(f'{what}: refused, element {i} is {type(element).__name__} '
                             f'{getattr(element, "dtype", "")}, not a numeric array')
    return array


def load_npz(path) -> dict:
    """Every member of the ``.npz`` file ``path`` as a numpy array (see the module docstring);
    a ValueError in one line if the file is not a readable ``.npz`` or any member is refused."""
    path = Path(path)
    out = {}
    try:
        with zipfile.ZipFile(path) as archive:
            for member in archive.namelist():
                if not member.endswith('.npy'):
                    raise ValueError(f'{path}: refused, member {member!r} is not an .npy array')
                out[member[:-4]] = _read_member(archive.read(member), f'{path} [{member}]')
    except (zipfile.BadZipFile, OSError, EOFError) as error:
        raise ValueError(f'{path}: not a readable .npz file ({error})') from None
    return out
