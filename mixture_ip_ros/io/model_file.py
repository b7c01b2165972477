"""Model files: a fitted MixtureIProMP as .npz (no pickle) plus a JSON metadata record.

Loading validates everything a consumer relies on (format version, shapes, finite values,
symmetric positive definite covariances, a probability vector of component weights) and
refuses a mismatched or corrupt file with a ModelFileError naming the file and the problem.

The metadata names every DOF and its unit, in column order: ``observed_names``,
``observed_units`` (P each), ``controlled_names``, ``controlled_units`` (Q each, Q >= 0);
``load_model(path)[1]`` returns it, :func:`model_layout` as a Layout. Format 1 files (wrist +
iiwa only, before units were recorded) load with units 'm' and 'rad'; files before format 4
(before the phase-speed weight) load with weight 1, the posterior they were used with. Format 4
is written so that an older package, which would drop the weight, refuses the file instead.
A model with phase warps (``model.warps_``, core.warped.PhaseWarps) adds their ``mean_`` and
``sd_`` as the arrays ``warp_mean`` and ``warp_sd`` and their ``failed_`` as the metadata
``warp_failed``; a file without them loads with the linear phase (``warps_`` None), and an
older package reading one uses the linear phase.

A model fitted with labels (MixtureIProMP.fit's ``labels``: all demonstrations named, or some)
records them as ``classes``, one per component, null for a component no label names (null
altogether without labels); ``component_labels`` is what a consumer shows for each component
(app.naming.named_components: the labels, and for the components they do not name, the
majority of their demonstrations' own labels).
"""

import json
import zipfile
from pathlib import Path

import numpy as np

from mixture_ip_ros import __version__
from mixture_ip_ros.core.basis import GaussianBasis
from mixture_ip_ros.core.demonstration import Layout
from mixture_ip_ros.core.mixture import MixtureIProMP
from mixture_ip_ros.core.novelty import NoveltyThresholds
from mixture_ip_ros.core.patterns import translation_groups
from mixture_ip_ros.core.warp import N_WARP, WIDTH
from mixture_ip_ros.core.warped import PhaseWarps
from mixture_ip_ros.io.files import write_atomic

FORMAT = 'mixture_ip_ros/mixture-iprompt'
FORMAT_VERSION = 4
_READABLE_VERSIONS = (1, 2, 3, 4)
_PARAMS = ('n_components', 'n_basis', 'method', 'ridge', 'prior_strength', 'prior_scale',
           'max_iter', 'tol', 'n_init', 'random_state', 'observation_noise', 'noise',
           'noise_var', 'speed_weight', 'translation', 'smoothing', 'switch_rate')
_ARRAYS = ('weights', 'means', 'covariances', 'noise_var', 'alpha_mean', 'alpha_std',
           'prior_cov', 'noise_time')
# The warp family a file's warp_mean / warp_sd are parameters of (core.warp).
_WARP_FAMILY = {'log_rate_bumps': N_WARP, 'bump_width': WIDTH}


class ModelFileError(ValueError):
    pass


def _jsonable_param(v):
    if isinstance(v, (tuple, list)):
        return [_jsonable_param(x) for x in v]
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    return v


def save_model(path, model: MixtureIProMP, *, layout: Layout = None, observed_names=None,
               controlled_names=None, observed_units=None, controlled_units=None,
               observed_frame='iiwa_link_0', component_labels=None, extra=None):
    """Write ``model`` to ``path`` (.npz), atomically (io.files). The DOF names (and units)
    consumers check against come from ``layout`` or from the name/unit lists (units default
    to '' = unspecified). The model's ``novelty_`` thresholds (core.novelty, calibrated at
    training) are kept when it has them."""
    model._check_fitted()
    model._check_params()
    if layout is None:
        if observed_names is None or controlled_names is None:
            raise ValueError('save_model needs a layout or observed_names and controlled_names')
        layout = Layout(tuple(observed_names), tuple(controlled_names), observed_units,
                        controlled_units)
    if len(layout.observed) != model.n_observed_ or len(layout.controlled) != model.n_controlled_:
        raise ValueError(f'need {model.n_observed_} observed and {model.n_controlled_} controlled '
                         f'names, got {len(layout.observed)} and {len(layout.controlled)}')
    meta = {
        'format': FORMAT, 'format_version': FORMAT_VERSION, 'package_version': __version__,
        'basis': model.basis_.to_dict(),
        'n_observed': model.n_observed_, 'n_controlled': model.n_controlled_,
        'observed_names': list(layout.observed), 'controlled_names': list(layout.controlled),
        'observed_units': list(layout.observed_units),
        'controlled_units': list(layout.controlled_units),
        'observed_frame': observed_frame,
        'params': {p: _jsonable_param(getattr(model, p)) for p in _PARAMS},
        'classes': (None if getattr(model, 'classes_', None) is None
                    else [_jsonable_param(c) for c in model.classes_]),
        'component_labels': list(component_labels) if component_labels is not None else None,
        'log_likelihood': [float(v) for v in model.log_likelihood_],
        'sample_period': float(model.sample_period_),
        # Fitted, for the record (the online estimator reads the means and covariances, which
        # hold them): the weights' smoothing per DOF and, with translation groups, the offsets'
        # mean and covariance.
        'smoothing': _jsonable_param(getattr(model, 'smoothing_', None)),
        'offsets': (None if getattr(model, 'offset_mean_', None) is None else
                    {'mean': model.offset_mean_.tolist(), 'cov': model.offset_cov_.tolist()}),
        'novelty': None if (novelty := getattr(model, 'novelty_', None)) is None else {
            'prefix': [float(v) for v in novelty.prefix], 'window': float(novelty.window),
            'window_size': novelty.window_size, 'min_interval': novelty.min_interval},
        'extra': extra or {},
    }
    arrays = {name: np.asarray(getattr(model, name + '_'), dtype=float) for name in _ARRAYS}
    warps = getattr(model, 'warps_', None)
    if warps is not None:                                   # the phase that bends, learned
        arrays.update(warp_mean=warps.mean_, warp_sd=warps.sd_)
        meta['warp'] = _WARP_FAMILY
        meta['warp_failed'] = [_jsonable_param(n) for n in warps.failed_]
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return write_atomic(path, lambda f: np.savez(f, metadata=np.array(json.dumps(meta)),
                                                 **arrays))


def load_model(path, *, observed_names=None, controlled_names=None):
    """Read and validate a model file; returns (model, metadata).

    If ``observed_names``/``controlled_names`` are given they must match the file's.
    """
    path = Path(path)

    def fail(msg):
        raise ModelFileError(f'model file {path}: {msg}')
    if not path.is_file():
        fail('does not exist')
    problem = _npz_problem(path)
    if problem:
        fail(problem)
    try:
        with np.load(path, allow_pickle=False) as npz:
            data = {k: npz[k] for k in npz.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as e:
        fail(f'not a readable .npz ({e})')
    if 'metadata' not in data:
        fail('no metadata record')
    try:
        meta = json.loads(str(data['metadata']))
    except json.JSONDecodeError as e:
        fail(f'metadata is not JSON ({e})')
    if meta.get('format') != FORMAT:
        fail(f"not a mixture_ip_ros model (format {meta.get('format')!r})")
    if meta.get('format_version') not in _READABLE_VERSIONS:
        fail(f"format version {meta.get('format_version')} is not supported "
             f'(this package reads {", ".join(map(str, _READABLE_VERSIONS))})')
    if meta['format_version'] == 1:       # wrist (m) + robot joints (rad) only
        meta.setdefault('observed_units', ['m'] * len(meta.get('observed_names', [])))
        meta.setdefault('controlled_units', ['rad'] * len(meta.get('controlled_names', [])))
    if meta['format_version'] < 3:        # before residual correlations: white noise
        data['noise_time'] = np.zeros(int(meta.get('n_observed', 0))
                                      + int(meta.get('n_controlled', 0)))
        meta.setdefault('sample_period', 0.0)
    missing = [a for a in _ARRAYS if a not in data]
    if missing:
        fail(f'missing arrays {missing}')
    for name in _ARRAYS:
        if not np.all(np.isfinite(data[name])):
            fail(f'{name} contains NaN or Inf')
    try:
        basis = GaussianBasis.from_dict(meta['basis'])
        P, Q = int(meta['n_observed']), int(meta['n_controlled'])
        params = meta['params']
        K = int(params['n_components'])
    except (KeyError, TypeError, ValueError) as e:
        fail(f'incomplete metadata ({e})')
    d = (P + Q) * basis.n_basis
    noise_shape = (K, P + Q) if params.get('noise') == 'per_component' else (P + Q,)
    expected = {'weights': (K,), 'means': (K, d), 'covariances': (K, d, d),
                'noise_var': noise_shape, 'alpha_mean': (K,), 'alpha_std': (K,),
                'prior_cov': (d, d), 'noise_time': (P + Q,)}
    for name, shape in expected.items():
        if data[name].shape != shape:
            fail(f'{name} has shape {data[name].shape}, expected {shape}')
    w = data['weights']
    if np.any(w <= 0) or abs(w.sum() - 1) > 1e-6:
        fail('component weights are not a probability vector')
    if np.any(data['alpha_mean'] <= 0) or np.any(data['alpha_std'] <= 0) or np.any(
            data['noise_var'] <= 0):
        fail('phase priors and noise variances must be positive')
    period = meta.get('sample_period')
    if (not isinstance(period, (int, float)) or not np.isfinite(period) or period < 0
            or np.any(data['noise_time'] < 0)):
        fail('the sample period and residual correlation times must be numbers >= 0')
    for k, C in enumerate(data['covariances']):
        if not np.allclose(C, C.T, rtol=0, atol=1e-10 * np.abs(C).max()):
            fail(f'covariance {k} is not symmetric')
        try:
            np.linalg.cholesky(C)
        except np.linalg.LinAlgError:
            fail(f'covariance {k} is not positive definite')
    for key, n in (('observed_names', P), ('controlled_names', Q), ('observed_units', P),
                   ('controlled_units', Q)):
        if not isinstance(meta.get(key), list) or len(meta[key]) != n:
            fail(f'{key} must list {n} entries, got {meta.get(key)!r}')
    for key, given in (('observed_names', observed_names), ('controlled_names', controlled_names)):
        if given is not None and list(given) != meta.get(key):
            fail(f'{key} {meta.get(key)} do not match the expected {list(given)}')
    model = MixtureIProMP(**{p: params[p] for p in _PARAMS if p in params})
    try:
        model._check_params()
        model.translation = translation_groups(model.translation, P + Q)
    except (TypeError, ValueError) as e:
        fail(f'invalid parameters ({e})')
    model.basis_ = basis
    model.n_observed_, model.n_controlled_ = P, Q
    for name in _ARRAYS:
        setattr(model, name + '_', data[name])
    model.log_likelihood_ = meta.get('log_likelihood', [])
    model.sample_period_ = float(period)
    try:
        smoothing = meta.get('smoothing')
        model.smoothing_ = None if smoothing is None else _finite(smoothing, (P + Q,))
        offsets = meta.get('offsets')
        if offsets is not None:
            g = len(model.translation or ())
            model.offset_mean_ = _finite(offsets['mean'], (g,))
            model.offset_cov_ = _finite(offsets['cov'], (g, g))
    except (KeyError, TypeError, ValueError) as e:
        fail(f'invalid fitted smoothing or offsets ({e})')
    classes = meta.get('classes')
    if classes is not None and (not isinstance(classes, list) or len(classes) != K or not all(
            c is None or isinstance(c, (str, int, float)) for c in classes)):
        fail(f'classes must be null or name each of the {K} components (null: a component no '
             f'label names), got {classes!r}')
    model.classes_ = classes
    model.warps_ = None                             # files without them: the linear phase
    failed = meta.get('warp_failed', [])
    if not isinstance(failed, list) or not all(isinstance(n, (str, int)) for n in failed):
        fail(f'warp_failed must list demonstration names or indices, got {failed!r}')
    if ('warp_mean' in data) != ('warp_sd' in data):
        fail('warp_mean and warp_sd go together')
    if 'warp_mean' in data:
        if meta.get('warp') != _WARP_FAMILY:
            fail(f"the phase warp is of another family ({meta.get('warp')!r}; this package's "
                 f'is {_WARP_FAMILY})')
        mean, sd = data['warp_mean'], data['warp_sd']
        if (mean.shape != (K, N_WARP) or sd.shape != (K, N_WARP)
                or not np.all(np.isfinite(mean)) or not np.all(np.isfinite(sd) & (sd > 0))):
            fail(f'the phase warp needs finite warp_mean and positive warp_sd of shape '
                 f'({K}, {N_WARP}), got {mean.shape} and {sd.shape}')
        model.warps_ = PhaseWarps()
        model.warps_.mean_, model.warps_.sd_, model.warps_.failed_ = mean, sd, failed
    try:
        model.novelty_ = novelty_thresholds(meta)
    except (KeyError, TypeError, ValueError) as e:
        fail(f'invalid novelty thresholds ({e})')
    return model, meta


def _finite(values, shape):
    a = np.asarray(values, dtype=float)
    if a.shape != shape or not np.all(np.isfinite(a)):
        raise ValueError(f'expected {shape} finite numbers, got shape {a.shape}')
    return a


def novelty_thresholds(meta):
    """The calibrated novelty thresholds in a model file's metadata, or None (a model trained
    before they existed)."""
    n = meta.get('novelty')
    if n is None:
        return None
    return NoveltyThresholds(np.asarray(n['prefix'], dtype=float), float(n['window']),
                             int(n['window_size']), float(n['min_interval']))


MAX_ARRAY_BYTES = 2**30   # no model is near this; a header declaring more is corrupt


def _npz_problem(path):
    """Why ``path`` cannot be a model's .npz, read from its headers before anything is
    allocated (a corrupt header must not make numpy reserve terabytes), or None."""
    try:
        archive = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError):
        return 'not a model file: not an .npz archive (write one with mixture-ip train)'
    with archive:
        for info in archive.infolist():
            if not info.filename.endswith('.npy'):
                return f'unexpected member {info.filename!r} (not an .npz of arrays)'
            try:
                with archive.open(info) as f:
                    version = np.lib.format.read_magic(f)
                    read_header = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                                   else np.lib.format.read_array_header_2_0)
                    shape, _, dtype = read_header(f)
            except Exception as e:    # numpy raises several types on a corrupt header
                return f'{info.filename}: unreadable array header ({e})'
            if dtype.hasobject:
                return f'{info.filename}: holds Python objects (a pickle), refused'
            nbytes = int(np.prod(shape, dtype=np.float64)) * dtype.itemsize
            if nbytes > MAX_ARRAY_BYTES or nbytes > info.file_size:
                return (f'{info.filename}: declares {nbytes} bytes of data but holds '
                        f'{info.file_size} (truncated or corrupt)')
    return None


def model_layout(meta) -> Layout:
    """The names and units of every DOF recorded in a model file's metadata."""
    return Layout(tuple(meta['observed_names']), tuple(meta['controlled_names']),
                  tuple(meta['observed_units']), tuple(meta['controlled_units']))
