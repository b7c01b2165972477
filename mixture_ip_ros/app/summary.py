"""What `mixture-ip train`, `evaluate` and `demo` print when they finish: a few lines a person
reads (the patterns found and their sizes, how clear the choice of K was, the held-out
quality), where the full JSON goes to a file (``--json``). Every key of that JSON is described
in docs/metrics.md."""

import json
import math
from pathlib import Path

import numpy as np

from mixture_ip_ros.app.naming import named_components

FRACTION_KEYS = ('0.3', '0.5', '0.7', '1')
_CRITERIA = {'patterns': 'the held-out likelihood of the patterns',
             'loo': "the leave-one-out error of the controlled agent (the thesis's)"}


def write_json(path, data) -> bool:
    """``data`` as indented JSON in the file ``path`` (a command's --json), if one is given;
    whether one was."""
    if path is None:
        return False
    from mixture_ip_ros.io.files import write_text_atomic
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(path, json.dumps(data, indent=1) + '\n')
    return True


def _num(x, spec='.2f'):
    return '-' if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, spec)


def _pct(x):
    return '-' if x is None else f'{100 * x:.0f}'


def pattern_lines(weights, sizes=None, names=None, durations=None) -> list:
    """A table of the components: members (training recordings each explains best), weight,
    mean duration (s) and name (the majority label of its members, '-' without labels)."""
    lines = ['  pattern  members  weight  duration  name']
    for k, w in enumerate(weights):
        size = '-' if sizes is None else str(sizes[k])
        duration = '-' if durations is None else f'{durations[k]:.2f} s'
        name = '-' if not names or names[k] is None else str(names[k])
        lines.append(f'  {k:>7d}  {size:>7s}  {w:6.2f}  {duration:>8s}  {name}')
    return lines


def selection_lines(info) -> list:
    """How K was chosen (training's summary ``info``): the criterion, its curve and whether
    it has a clear optimum, with what to try when it has none."""
    sel = info.get('selection')
    K = info.get('n_components')
    if sel is None:
        how = 'one per label (supervised)' if info.get('supervised') else 'given (--components)'
        return [f'K = {K}: {how}']
    candidates = sel['candidates']
    span = (f'{candidates[0]}..{candidates[-1]}' if len(candidates) > 1
            else str(candidates[0]))
    clear = 'a clear optimum' if sel['clear_optimum'] else 'NO clear optimum'
    lines = [f"K = {sel['chosen']} chosen over {span} by "
             f"{_CRITERIA.get(sel['criterion'], sel['criterion'])}: {clear}"]
    better = 'higher' if sel['criterion'] == 'patterns' else 'lower'
    unit = 'nats per recording' if sel['criterion'] == 'patterns' else sel.get('unit', '')
    curve = '  '.join(f"{k}: {m:.3g}{'*' if k == sel['chosen'] else ''}"
                      for k, m in zip(candidates, sel['mean']))
    lines.append(f'  K curve ({unit}, {better} is better): {curve}')
    # keyed by K in memory, by its text in a file's JSON
    stability = {str(k): v for k, v in (sel.get('stability') or {}).items()}
    if str(sel['chosen']) in stability:
        lines.append(f"  its partition reproduced on subsamples: "
                     f"{stability[str(sel['chosen'])]:.2f} (median agreement, 1 = always)")
    if not sel['clear_optimum']:
        lines.append(f"  the curve is flat ({sel['note']}): if you know how many patterns "
                     f"there are, give --components K; otherwise record more of each pattern "
                     f"({info.get('n_demonstrations', '?')} recordings now)")
    return lines


def model_lines(info) -> list:
    """The rest of training's decisions: phase, speed weight, covariance floor."""
    phase = info.get('phase') or {}
    chosen = phase.get('chosen', 'linear' if 'phase' not in info else '?')
    gain = phase.get('held_out_gain')
    why = ('' if gain is None else
           f' (a warp predicts held-out recordings {abs(gain):.2f} nats each '
           f'{"better" if gain > 0 else "worse"} than the linear phase)')
    lines = [f'phase: {chosen}{why}',
             f"speed weight {_num(info.get('speed_weight'), 'g')}, switch rate "
             f"{_num(info.get('switch_rate'), 'g')}/s, covariance floor "
             f"{_num(info.get('prior_scale'), 'g')}"]
    if info.get('warp_failed'):
        lines.append(f"the phase warp did not converge for {len(info['warp_failed'])} "
                     f"recording(s): {', '.join(info['warp_failed'][:5])}")
    return lines


def train_summary(info, model_path, weights=None, names=None, durations=None,
                  csv_dir=None) -> str:
    """`mixture-ip train`'s summary of training's ``info``: the patterns found (``weights``,
    ``names`` and mean ``durations`` of the components where known), how K was chosen, the
    model's other decisions and how to measure it on labelled recordings."""
    K = info.get('n_components', '?')
    lines = [f"{model_path}: {K} pattern{'s' if K != 1 else ''} in "
             f"{info.get('n_demonstrations', '?')} recordings"]
    if weights is not None:
        lines += pattern_lines(weights, info.get('component_sizes'), names, durations)
    if 'n_components' in info:
        lines += selection_lines(info) + model_lines(info)
    lines += [f'next: mixture-ip info {model_path} shows it again; with labelled recordings,',
              f"  mixture-ip evaluate --model {model_path} --csv {csv_dir or 'DIR'} --labels "
              'labels.json scores it (recognition, partner error), and evaluate --csv without '
              '--model cross-validates training itself']
    return '\n'.join(lines)


def train_report(model, info, demos, model_path, csv_dir=None) -> str:
    """:func:`train_summary` of a model just trained on ``demos``, its components named as its
    file names them (app.naming.named_components)."""
    if model is None:
        return train_summary(info, model_path, csv_dir=csv_dir)
    return train_summary(info, model_path, np.asarray(model.weights_),
                         named_components(model, demos), 1.0 / np.asarray(model.alpha_mean_),
                         csv_dir)


# ----------------------------------------------------------------------------------- evaluate

def _row(label, values, keys=FRACTION_KEYS, fmt=_pct, width=26):
    values = values or {}
    return f'  {label:<{width}s}' + ''.join(f'{fmt(values.get(k)):>7s}' for k in keys)


def labelled_lines(m) -> list:
    """The table of a labelled evaluation (cross-validated: `evaluate --csv`, NuiSI; or a
    trained model scored: `evaluate --model`)."""
    lines = [f"{m['n_recordings']} recordings of {len(m['interactions'])} labels "
             f"({', '.join(map(str, m['interactions']))})"]
    if 'n_components_selected' in m:
        lines += [f"K per fold {', '.join(map(str, m['n_components_selected']))}; patterns "
                  f"found vs labels (ARI, 1 = the same partition):",
                  f"  training {_num(m['ari'])}, held out {_num(m['heldout_ari'])} (k-means "
                  f"{_num(m.get('baseline_kmeans_ari'))}, GMM "
                  f"{_num(m.get('baseline_gmm_pca_ari'))}, given the true K)"]
    else:
        lines.append(f"model: K = {m['n_components']}, components named "
                     f"{', '.join(map(str, m['component_labels']))} (majority of these "
                     f"recordings); patterns vs labels ARI {_num(m['ari'])}")
    keys = [k for k in FRACTION_KEYS if k in m['recognition_accuracy_by_fraction']]
    head = ''.join(f'{float(k) * 100:>6.0f}%' for k in keys)
    lines.append(f"  {'recognised (%) from':<26s}{head}")
    for label, key in (('mixture, online', 'recognition_accuracy_by_fraction'),
                       ('mixture, phase known', 'phase_known_accuracy_by_fraction'),
                       ('supervised mixture', 'supervised_accuracy_by_fraction'),
                       ('one ProMP (K = 1)', 'single_accuracy_by_fraction'),
                       ('nearest recording (DTW)', 'baseline_nn_accuracy_by_fraction')):
        if key in m:
            lines.append(_row(label, m[key], keys))
    chance = m.get('chance_accuracy')
    if chance is not None:
        lines.append(_row('chance (largest label)', {k: chance for k in keys}, keys))
        single = m.get('single_accuracy_by_fraction') or {}
        if any(v is not None and v < chance for v in single.values()):
            lines.append('  (one ProMP names every recording with its training majority label, '
                         'so it can score below chance: docs/metrics.md)')
    lines += confusion_lines(m.get('recognition_confusion_by_fraction') or {})
    unit = next((u for u in ('cm', 'unit') if f'partner_rms_{u}_by_fraction' in m), None)
    if unit is not None:
        rest = [k for k in keys if k != '1']
        unit_name = 'cm' if unit == 'cm' else 'DOF unit'
        lines.append(f"  {f'partner RMS ({unit_name}) after':<26s}"
                     + ''.join(f'{float(k) * 100:>6.0f}%' for k in rest))
        for label, prefix in (('mixture', ''), ('supervised mixture', 'supervised_'),
                              ('one ProMP (K = 1)', 'single_'),
                              ('nearest recording (DTW)', 'baseline_nn_')):
            key = f'{prefix}partner_rms_{unit}_by_fraction'
            if key in m:
                lines.append(_row(label, m[key], rest, lambda x: _num(x, '.1f')))
    return lines


def confusion_lines(by_fraction, key='0.5') -> list:
    """The recordings of each label (rows) by the label recognised online (columns) at half
    the movement, when some were taken for another: which pattern is confused with which."""
    table = by_fraction.get(key)
    if not table or all(n == 0 for row, counts in table.items() for said, n in counts.items()
                        if said != row):
        return []
    columns = list(next(iter(table.values())))
    width = max(6, *(len(str(c)) + 1 for c in columns))
    lines = [f"  {f'recognised as, at {float(key) * 100:.0f} %':<26s}"
             + ''.join(f'{str(c):>{width}s}' for c in columns)]
    for row, counts in table.items():
        lines.append(f'  {str(row):<26s}' + ''.join(f'{counts[c]:>{width}d}' for c in columns))
    return lines


def _scalar_lines(m, limit=14) -> list:
    """The plain numbers of a scenario's metrics (and its per-fraction tables as one row
    each), for scenarios without a table of their own."""
    skip = {'seed', 'quick', 'runtime_s', 'config', 'plots', 'units', 'source', 'scenario',
            'robot', 'n_folds'}
    lines = []
    for key, v in m.items():
        if key in skip or key.endswith('_s'):
            continue
        if isinstance(v, bool) or isinstance(v, str):
            lines.append(f'  {key}: {v}')
        elif isinstance(v, (int, float)):
            lines.append(f'  {key}: {_num(v, ".3g")}')
        elif (isinstance(v, dict) and 0 < len(v) <= 6
              and all(isinstance(x, (int, float)) or x is None for x in v.values())):
            lines.append(f'  {key}: ' + ', '.join(f'{k} {_num(x, ".3g")}' for k, x in v.items()))
    if len(lines) > limit:
        lines = lines[:limit] + [f'  ... and {len(lines) - limit} more']
    return lines


def change_of_mind_lines(m) -> list:
    """The change-of-mind evaluation of one data set (app.evaluation.change_of_mind)."""
    lines = []
    for method, name in (('switching', 'switching'), ('no_switch', 'never switching')):
        x = m[method]
        d = {k: 'never' if v is None or v == math.inf else f'{v:.2f} s'
             for k, v in x['delay_s'].items()}
        un = x['unchanged_recognised']
        hand = x['hand_error_end_cm']
        lines += [f"{name}: {x['splices']} changes of mind followed {_pct(x['followed'])} %, "
                  f"settled after {d['median']} (median), {d['p90']} (90 %)",
                  f"  unchanged recordings recognised {' / '.join(_pct(v) for v in un.values())}"
                  f" % at {' / '.join(f'{100 * float(k):.0f}' for k in un)} % of the movement; "
                  f"belief changed after 30 % in {_pct(x['unchanged_late_changes'])} %",
                  f"  partner's hand at the end {_num(hand['spliced'], '.1f')} cm off "
                  f"(unchanged: {_num(hand['unchanged'], '.1f')} cm)"]
    return lines


def evaluate_summary(metrics, written=()) -> str:
    """`mixture-ip evaluate`'s summary of ``metrics``; ``written``: the files the full
    metrics went to."""
    m = metrics
    title = m.get('scenario', 'model')
    if 'model' in m:
        lines = [f"{m['model']} scored on {m.get('source', 'the recordings')} "
                 '(no retraining)']
        lines += labelled_lines(m)
    elif 'recognition_accuracy_by_fraction' in m and 'n_recordings' in m:
        lines = [f"{title}: {m['n_folds']}-fold cross-validation, each fold trained without "
                 'its held-out recordings']
        lines += labelled_lines(m)
    else:
        sets = [k for k, v in m.items() if isinstance(v, dict) and 'n_recordings' in v]
        changes = [k for k, v in m.items() if isinstance(v, dict) and 'switching' in v]
        lines = [f'{title}:']
        for name in sets:
            lines += [f'{name}:'] + ['  ' + ln for ln in labelled_lines(m[name])]
        for name in changes:
            lines += [f'{name}:'] + ['  ' + ln for ln in change_of_mind_lines(m[name])]
        if not sets and not changes:
            lines += _scalar_lines(m)
    if (m.get('runtime_s') or 0) >= 1:
        lines.append(f"took {m['runtime_s']:.0f} s")
    if written:
        lines.append(f"full metrics: {', '.join(map(str, written))} (every key: docs/metrics.md)")
    return '\n'.join(lines)


# --------------------------------------------------------------------------------------- demo

def demo_summary(report, json_path=None) -> str:
    """`mixture-ip demo`'s closing lines (box assembly or interactions report)."""
    rows = report.get('interactions') or []
    n = len(rows)
    right = sum(r.get('true_pattern') == r.get('chosen_pattern') for r in rows)
    lines = [f'{right} of {n} interactions recognised; committed on average at '
             f"{_num(report.get('commit_fraction_mean'))} of the motion"]
    if report.get('hand_error_cm_mean') is not None:
        lines.append(f"hand to the demonstrated target: {_num(report['hand_error_cm_mean'], '.1f')}"
                     f" cm mean, {_num(report.get('hand_error_cm_max'), '.1f')} cm worst")
    if report.get('flange_to_partner_rms_cm_mean') is not None:
        lines.append(f"flange to the partner's recorded hand: "
                     f"{_num(report['flange_to_partner_rms_cm_mean'], '.1f')} cm RMS after the "
                     f"commit, {_num(report.get('flange_to_partner_end_cm_mean'), '.1f')} cm "
                     'at the end')
    tracking = report.get('tracking_rms_mrad_mean', report.get('tracking_rms_mrad_max'))
    if tracking is not None:
        lines.append(f'joint tracking RMS {_num(tracking, ".2f")} mrad')
    latency = report.get('latency') or {}
    if latency.get('update_us_mean') is not None:
        lines.append(f"estimator update {_num(latency['update_us_mean'], '.0f')} us mean, "
                     f"{_num(latency.get('update_us_max'), '.0f')} us worst")
    if json_path:
        lines.append(f'full report: {json_path} (every key: docs/metrics.md)')
    return '\n'.join(lines)
