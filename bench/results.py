"""docs/results.md from the evaluations, demos and benches, run here and now: the tables cannot
drift from what the code gives.

Runs every `mixture-ip evaluate` scenario, the closed-loop demo for every shipped arm (and with
every command delayed), the interactions demo, and the benches (training, the estimator's
update, the simulation, the soak, recognition once the end is known), each into
out/results/<name>.json, then writes docs/results.md with the date, the machine and the commit.
``--reuse`` keeps the JSON already in out/results (to rewrite the page after one part was
rerun). About an hour on 2 cores. The experiments (experiments/, docs/method.md) are not run.

    .venv/bin/python bench/results.py [--reuse] [--only NAME,...]
"""

import argparse
import datetime
import json
import os
from pathlib import Path
import platform
import subprocess
import sys

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / 'out' / 'results'
BIN = Path(sys.executable).parent
SCENARIOS = ('box_assembly', 'pole', 'phase', 'missing_data', 'gestures', 'interactions',
             'change_of_mind')
ROBOTS = ('iiwa14', 'panda', 'ur5')
DELAYS = (0.02, 0.05, 0.1)


def jobs():
    """name -> (command, the file its JSON lands in, or None: the command's last line)."""
    out = {}
    for s in SCENARIOS:
        folder = OUT / f'evaluate_{s}'
        out[f'evaluate_{s}'] = ([str(BIN / 'mixture-ip'), 'evaluate', '--scenario', s, '--out',
                                 str(folder)], folder / 'metrics.json')
    for r in ROBOTS:
        out[f'demo_{r}'] = ([str(BIN / 'mixture-ip'), 'demo', '--robot', r, '--json',
                             str(OUT / f'demo_{r}.json')], OUT / f'demo_{r}.json')
    for d in DELAYS:
        name = f'demo_iiwa14_delay_{int(d * 1000)}ms'
        out[name] = ([str(BIN / 'mixture-ip'), 'demo', '--command-delay', str(d), '--json',
                      str(OUT / f'{name}.json')], OUT / f'{name}.json')
    out['interactions'] = ([sys.executable, str(ROOT / 'bench' / 'interactions.py'), '--robots',
                            'iiwa14', '--out', str(OUT / 'interactions')], None)
    out['robustness'] = ([sys.executable, str(ROOT / 'bench' / 'robustness.py'), '--out',
                          str(OUT / 'robustness')], None)
    out['cpu_kernels'] = ([sys.executable, str(ROOT / 'bench' / 'cpu_kernels.py')], None)
    out['end_recognition'] = ([sys.executable, str(ROOT / 'bench' / 'end_recognition.py')],
                              None)
    out['train'] = ([sys.executable, str(ROOT / 'bench' / 'train.py')], None)
    out['train_scaling'] = ([sys.executable, str(ROOT / 'bench' / 'train_scaling.py')], None)
    out['estimator'] = ([sys.executable, str(ROOT / 'bench' / 'estimator.py')], None)
    out['sim'] = ([sys.executable, str(ROOT / 'bench' / 'sim.py')], None)
    out['soak'] = ([sys.executable, str(ROOT / 'bench' / 'soak.py'), '--minutes', '3', '--load',
                    '2'], None)
    return out


def run(name, command, target) -> dict:
    path = OUT / f'{name}.json'
    env = dict(os.environ, OPENBLAS_NUM_THREADS='1')
    print(f'[results] {name}: {" ".join(command)}', file=sys.stderr, flush=True)
    done = subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f'{name} failed ({done.returncode}): '
                           f'{(done.stderr or done.stdout).strip().splitlines()[-1:]}')
    if target is None:
        lines = [ln for ln in done.stdout.strip().splitlines() if ln.startswith('{')]
        result = json.loads(lines[-1])
        if name == 'interactions':       # one object per (arm, model), then the summary
            result = {'runs': [json.loads(ln) for ln in lines]}
    else:
        result = json.loads(Path(target).read_text())
    path.write_text(json.dumps(result))
    return result


def change_of_mind_section(c) -> list:
    """`evaluate --scenario change_of_mind`: NuiSI recordings spliced into changes of mind."""
    if not c:
        return []

    def delay(x):
        return 'never' if x is None else f'{x:.2f} s'
    L = ['## Changes of mind: NuiSI recordings spliced (5-fold cross-validation)', '',
         'Every ordered pair of held-out recordings of different interactions, joined at 30-60 % '
         'of the first (core.splice); the same model read with the switch rate training '
         'calibrated and with rate 0 (a belief that never switches).', '',
         '| | v1 switching | v1 never | v2 switching | v2 never |', '|---|---|---|---|---|']
    rows = [('changes of mind', lambda x: str(x['splices'])),
            ('followed (belief at the end)', lambda x: pct(x['followed'])),
            ('settled after (median / 90 %)', lambda x: f"{delay(x['delay_s']['median'])} / "
                                                        f"{delay(x['delay_s']['p90'])}"),
            ('unchanged recognised, 30/50/70/100 %',
             lambda x: fractions(x['unchanged_recognised']) + ' %'),
            ('unchanged: belief changed after 30 %',
             lambda x: pct(x['unchanged_late_changes'])),
            ('partner at the end, changed / unchanged',
             lambda x: f"{x['hand_error_end_cm']['spliced']:.1f} / "
                       f"{x['hand_error_end_cm']['unchanged']:.1f} cm")]
    for name, f in rows:
        L.append(f'| {name} | ' + ' | '.join(f(c[v][m]) for v in ('v1', 'v2')
                                              for m in ('switching', 'no_switch')) + ' |')
    L.append('| switch rate per fold (1/s) | ' + ' | '.join(
        ', '.join(f"{f['switch_rate']:g}" for f in c[v]['folds']) + ' | -'
        for v in ('v1', 'v2')) + ' |')
    return L + ['']


def machine() -> str:
    model = next((ln.split(':', 1)[1].strip() for ln in
                  Path('/proc/cpuinfo').read_text().splitlines()
                  if ln.startswith('model name')), platform.processor())
    load = ', '.join(f'{x:.1f}' for x in os.getloadavg())
    return f'{os.cpu_count()} cores ({model}), load average {load} when the page was written'


def fmt(x, spec):
    return '-' if x is None else format(x, spec)


def pct(x):
    return '-' if x is None else f'{100 * x:.0f} %'


def wrong_side(pole, model):
    """'n of m': one-sided spots the ``model`` ('single' or 'mixture') takes round the wrong
    side of the pole."""
    one_sided = pole['n_folds'] - pole['n_two_sided_spots']
    right = pole[f'side_accuracy_{model}']['one_sided']
    return '-' if right is None else f'{round((1 - right) * one_sided)} of {one_sided}'


def fractions(d, keys=('0.3', '0.5', '0.7', '1')):
    return ' / '.join('-' if d.get(k) is None else
                      (f'{100 * d[k]:.0f}' if d[k] <= 1.0001 else f'{d[k]:.1f}') for k in keys)


def cm(d, keys=('0.3', '0.5', '0.7')):
    return ' / '.join('-' if d.get(k) is None else f'{d[k]:.1f}' for k in keys)


ROBUSTNESS_ROWS = (
    ('clean', 'as recorded'), ('clean_shared', 'as recorded, `--translation shared`'),
    ('offset', 'pair elsewhere (a)'), ('offset_none', 'pair elsewhere, `--translation none`'),
    ('noise', 'tracker noise (b)'), ('clock', 'tracker clock (c)'),
    ('half', 'half the training recordings (d)'), ('all', '(a) + (b) + (c)'),
    ('all_none', '(a) + (b) + (c), `--translation none`'), ('all_half', '(a) + (b) + (c) + (d)'),
    ('tempo', "the people's pace (e)"), ('tempo_half', '(e) + (d)'),
    ('tempo_abc', '(e) + (a) + (b) + (c)'),
    ('tempo_one_label', '(e), one training recording of each interaction labelled (ARI: the '
                        'others)'))


def robustness_section(rob, kernels) -> list:
    """The robustness table (bench/robustness.py) and the kernels' decisions
    (bench/cpu_kernels.py)."""
    L = []
    if rob:
        m = rob['magnitudes']
        L += ['## Recorded as another lab would: NuiSI corrupted (`bench/robustness.py`)', '',
              f"Seed {rob['seed']}. (a) each recording's pair elsewhere: one offset for both "
              f"people, std {' / '.join(f'{100 * x:.0f}' for x in m['offset_std'])} cm per axis; "
              f"(b) a tracker's noise on every coordinate, {100 * m['noise_std']:.0f} cm "
              f"correlated over {m['noise_time']:g} s; (c) stamps jittered by "
              f"{1000 * m['jitter_std']:.0f} ms, {100 * m['drop']:.0f} % of the frames dropped "
              f"in bursts of 1-{m['burst']}; (d) each fold trained on "
              f"{100 * m['train_fraction']:.0f} % of its training recordings; (e) the people's "
              f"pace within each recording, log pace std {m['tempo_std']:g} correlated over "
              f"{100 * m['tempo_time']:.0f} % of the movement, onset and end kept. Shifted "
              "data are trained with `--translation shared` unless the row says otherwise; the "
              "nearest-neighbour baseline is given the same knowledge (derivative DTW). "
              'Recognition at 30 / 50 / 70 / 100 %, partner RMS in cm at 30 / 50 / 70 %.', '']
        for v in ('v1', 'v2'):
            if v not in rob:
                continue
            L += [f'NuiSI {v}:', '', '| data | K per fold | ARI (k-means) | recognised | '
                  'supervised | 1-NN DTW | partner (x clean at 50 %) | nearest neighbour |',
                  '|---|---|---|---|---|---|---|---|']
            for case, name in ROBUSTNESS_ROWS:
                c = rob[v].get(case)
                if not c:
                    continue
                ratio = (c.get('partner_vs_clean') or {}).get('0.5')
                ari = c.get('unlabelled_ari', c['ari'])     # semi-supervised: the unlabelled
                L.append(f"| {name} | {', '.join(map(str, c['k']))} | {ari:.2f} "
                         f"({c['kmeans_ari']:.2f}) | {fractions(c['recognised'])} % | "
                         f"{fractions(c['supervised'])} % | {fractions(c['nn_dtw'])} % | "
                         f"{cm(c['partner_cm'])} ({'-' if ratio is None else f'{ratio:.2f}'}) | "
                         f"{cm(c['nn_partner_cm'])} |")
            L.append('')
    if kernels:
        same = 'the same' if kernels['same'] else 'NOT the same'
        L += ['## The same decisions on every CPU (`bench/cpu_kernels.py`)', '',
              f"Training's decisions (K, partition, floor, speed weight) on the layouts test's "
              f"sets under the OpenBLAS kernels {', '.join(kernels['kernels'])}: {same}; the "
              f"curves behind them differ by {kernels['curve_max_relative_difference']:.1e} "
              'relative at most.', '']
    return L


def end_section(er) -> list:
    """Recognition given the end, the linear phase against each component's warp
    (bench/end_recognition.py)."""
    versions = [v for v in ('v1', 'v2') if v in (er or {})]
    if not versions:
        return []
    cases = [(v, c) for v in versions for c in ('clean', 'tempo') if c in er[v]]
    names = {'clean': 'as recorded', 'tempo': 'pace changed'}
    methods = [m for m in er[versions[0]]['clean']
               if m not in ('k', 'warp_fits_not_converged', 'chose_warped')]
    L = ['## Recognised once the end is known: the phase that bends (`bench/end_recognition.py`)',
         '', "The interactions evaluation's 5 stratified folds; each held-out recording played "
         "to the estimator, then its end given (the observer's 'end' event: "
         '`OnlineEstimator.end_posterior`). "warped": each component\'s warp integrated out '
         "under the component's Gaussian over it (thesis eq. 34, learned by training); "
         '"linear, same samples": the same model with the warp pinned at b = 0 (the phase alone '
         'differs); "linear, every sample": without warps, as a model without them reads the '
         "recording. \"pace changed\": the robustness bench's `tempo`. Percent of the held-out "
         'recordings; K chosen per fold; warp fits not converged: ' + ', '.join(
             f"{v} {names[c]} {er[v][c]['warp_fits_not_converged']}" for v, c in cases) + '.',
         '',
         '| method | ' + ' | '.join(f'NuiSI {v}, {names[c]}' for v, c in cases) + ' |',
         '|---|' + '---|' * len(cases)]
    L += [f'| {m} | ' + ' | '.join(f'{er[v][c][m]:.1f} %' for v, c in cases) + ' |'
          for m in methods]
    L.append('| K per fold | ' + ' | '.join(', '.join(map(str, er[v][c]['k'])) for v, c in cases)
             + ' |')
    if all('chose_warped' in er[v][c] for v, c in cases):
        L.append('| models given the warps by training (held-out choice) | '
                 + ' | '.join(er[v][c]['chose_warped'] for v, c in cases) + ' |')
    return L + ['']


def page(R: dict) -> str:
    commit = subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], cwd=ROOT,
                            capture_output=True, text=True).stdout.strip()
    L = ['# Results', '',
         f'Written by `bench/results.py` on {datetime.date.today()} at commit `{commit}`, on '
         f'{machine()}. Every number below is from that run; rerun the script to check them.',
         '']
    box = R.get('evaluate_box_assembly')
    if box:
        L += ['## Box assembly (thesis 3.4.2; generated, 48 demonstrations, leave-one-out)', '',
              '| K | final selection | online selection at 30 / 50 / 70 % | hand error plate '
              '(mean, 2 sigma) | screwdriver | thesis |', '|---|---|---|---|---|---|',
              f"| {box['n_components_selected']} | {pct(box['selection_accuracy_final'])} | "
              f"{fractions(box['selection_accuracy_by_fraction'], ('0.3', '0.5', '0.7'))} % | "
              f"{box['hand_error_cm']['plate'][0]:.2f} +- {box['hand_error_cm']['plate'][1]:.2f}"
              f" cm | {box['hand_error_cm']['screwdriver'][0]:.2f} +- "
              f"{box['hand_error_cm']['screwdriver'][1]:.2f} cm | K = 3, 100 %, 3.2 +- 2.6 / "
              '2.1 +- 2.3 cm |', '']
    pole = R.get('evaluate_pole')
    if pole:
        L += ['## Pole (thesis 3.4.1; 28 demonstrations)', '',
              f"K = {pole['n_components_selected']} (the thesis's leave-one-out curve at that "
              f"floor: {pole['n_components_thesis_loo']}). Predicted arm paths through the pole: "
              f"one Gaussian {pct(pole['pole_collision_rate_single'])}, the mixture "
              f"{pct(pole['pole_collision_rate_mixture'])}. Flange RMS on spots reachable from "
              f"one side: one Gaussian {pole['flange_rms_cm_single_one_sided']:.1f} cm, the "
              f"mixture {pole['flange_rms_cm_mixture_one_sided']:.1f} cm (thesis: about 4 cm); "
              f"one-sided spots the mixture takes round the wrong side: "
              f"{wrong_side(pole, 'mixture')}, one Gaussian {wrong_side(pole, 'single')}.", '']
    ph, md = R.get('evaluate_phase'), R.get('evaluate_missing_data')
    if ph and md:
        rms = ph['rms_at']
        L += ['## Letters (thesis 4.3; 20 train / 20 test)', '',
              f"Phase: completion RMS at 20 / 40 / 60 / 80 / 100 % observed "
              f"{' / '.join(f'{rms[k][0]:.3f}' for k in ('0.2', '0.4', '0.6', '0.8', '1'))}; "
              f"alpha within one grid step for {pct(ph['alpha_accuracy_at_40'])} of the test "
              f"letters at 40 %, median error {100 * ph['alpha_rel_error_median_at_40']:.2f} %.",
              f"Missing data: EM better than per-trajectory regression at "
              f"{md['paired']['em_significantly_better']} of {md['paired']['n_fractions']} "
              f"observed fractions (paired, two standard errors), regression better at "
              f"{md['paired']['regression_significantly_better']}; EM's log-likelihood "
              f"{'rises monotonically' if md['em_loglik_monotone'] else 'is NOT monotone'}.",
              '']
    g = R.get('evaluate_gestures')
    if g:
        L += ['## Real human motion, one agent: PickupGestureWiimoteZ (50 train / 50 test)', '',
              'Who made the gesture, accuracy at 30 / 50 / 70 / 100 % of it (chance 10 %).', '',
              '| method | accuracy |', '|---|---|',
              f"| mixture, unsupervised (K = {g['n_components_selected']} chosen), online | "
              f"{fractions(g['unsupervised_accuracy_by_fraction'])} % |",
              f"| mixture, supervised, online | {fractions(g['supervised_accuracy_by_fraction'])}"
              ' % |',
              f"| mixture, supervised, phase known | "
              f"{fractions(g['supervised_accuracy_phase_known_by_fraction'])} % |",
              f"| per-class ProMP (baseline, ridge chosen by cross-validation) | "
              f"{fractions(g['baseline_promp_accuracy_by_fraction'])} % |",
              f"| scikit-learn GaussianMixture, K = {g['n_components_selected']} | "
              f"{pct(g['baseline_sklearn_gmm_accuracy'])} (whole) |",
              f"| 1-NN DTW | {pct(g['baseline_dtw_accuracy'])} (whole) |",
              f"| reference, K = 10 given: mixture, online | "
              f"{fractions(g['reference_k_classes']['unsupervised_accuracy_by_fraction'])} % |",
              '']
    it = R.get('evaluate_interactions')
    if it:
        L += ['## Real two-person interactions: NuiSI (5-fold cross-validation)', '',
              'K chosen inside each fold from its training recordings; labels only name the '
              'components. Partner: the controlled agent (person 2\'s hand) predicted over the '
              'rest of the interaction, RMS in cm at 30 / 50 / 70 % observed.', '',
              '| | v1 (6 interactions, 114) | v2 (4 interactions, 44) |', '|---|---|---|']
        v1, v2 = it['v1'], it['v2']
        rows = [('K per fold', lambda m: ', '.join(map(str, m['n_components_selected']))),
                ('ARI, training recordings', lambda m: f"{m['ari']:.2f}"),
                ('ARI, held-out recordings', lambda m: f"{m['heldout_ari']:.2f}"),
                ('baseline k-means ARI (true K)', lambda m: f"{m['baseline_kmeans_ari']:.2f}"),
                ('baseline GMM on 8 PCs ARI (true K)',
                 lambda m: f"{m['baseline_gmm_pca_ari']:.2f}"),
                ('recognised, online, 30/50/70/100 %',
                 lambda m: fractions(m['recognition_accuracy_by_fraction']) + ' %'),
                ('supervised mixture',
                 lambda m: fractions(m['supervised_accuracy_by_fraction']) + ' %'),
                ('baseline 1-NN open-end DTW',
                 lambda m: fractions(m['baseline_nn_accuracy_by_fraction']) + ' %'),
                ('partner RMS, mixture', lambda m: cm(m['partner_rms_cm_by_fraction'])),
                ('partner RMS, K = 1', lambda m: cm(m['single_partner_rms_cm_by_fraction'])),
                ('partner RMS, supervised',
                 lambda m: cm(m['supervised_partner_rms_cm_by_fraction'])),
                ('partner RMS, nearest neighbour',
                 lambda m: cm(m['baseline_nn_partner_rms_cm_by_fraction'])),
                ('partner at the end, mixture', lambda m: cm(m['partner_final_cm_by_fraction'])),
                ('partner at the end, nearest neighbour',
                 lambda m: cm(m['baseline_nn_partner_final_cm_by_fraction'])),
                ('partner at the contact (hands closest; people '
                 '{people}), mixture', lambda m: cm(m['partner_contact_cm_by_fraction'])),
                ('partner at the contact, supervised',
                 lambda m: cm(m['supervised_partner_contact_cm_by_fraction'])),
                ('partner at the contact, nearest neighbour',
                 lambda m: cm(m['baseline_nn_partner_contact_cm_by_fraction'])),
                ('contact already observed',
                 lambda m: fractions(m['contact_observed_share_by_fraction']) + ' %'),
                ('phase error (alpha* f T against f), mixture',
                 lambda m: ' / '.join(f'{v:.3f}' for v in
                                      list(m['phase_error_by_fraction'].values())[:3])),
                ('speed weight per fold (training calibrates it)',
                 lambda m: ', '.join(f"{p['speed_weight']:g}" for p in m['folds']))]
        people = ' / '.join(f"{m['people_contact_distance_cm']:.1f}" for m in (v1, v2))
        L += [f'| {name.format(people=people + " cm")} | {f(v1)} | {f(v2)} |'
              for name, f in rows] + ['']
    L += change_of_mind_section(R.get('evaluate_change_of_mind'))
    L += end_section(R.get('end_recognition'))
    L += robustness_section(R.get('robustness'), R.get('cpu_kernels'))
    demos = [(r, R.get(f'demo_{r}')) for r in ROBOTS]
    if any(d for _, d in demos):
        L += ['## Closed loop (`mixture-ip demo`, box assembly, the real nodes on simulated '
              'time)', '', '| run | right pattern | K | committed after (mean) | hand from '
              'target, mean | tracking RMS, max | refused |', '|---|---|---|---|---|---|---|']
        runs = demos + [(f'iiwa14, commands {int(d * 1000)} ms late',
                         R.get(f'demo_iiwa14_delay_{int(d * 1000)}ms')) for d in DELAYS]
        for name, d in runs:
            if d:
                rows = d['interactions']
                right = sum(r['true_pattern'] == r['chosen_pattern'] for r in rows)
                refused = sum(r['commands_refused'] or 0 for r in rows)
                L.append(f"| {name} | {right}/{len(rows)} | {d['n_components']} | "
                         f"{pct(d['commit_fraction_mean'])} | {d['hand_error_cm_mean']:.2f} cm |"
                         f" {d['tracking_rms_mrad_max']:.3f} mrad | {refused} |")
        L.append('')
    ints = R.get('interactions')
    if ints:
        L += ['## The robot takes a person\'s part (`mixture-ip demo --scenario interactions`, '
              'NuiSI v2\'s 11 held-out recordings, iiwa)', '',
              '| model | right interaction | committed (mean) | flange to partner after '
              'commitment, RMS: loop / offline | from the onset | at the end: loop / offline | '
              'at the contact, flange / partner to person 1: all; handshakes and fist bumps | '
              'committed after the contact | tracking RMS, max | '
              'refused | beyond limits |',
              '|---|---|---|---|---|---|---|---|---|---|---|']
        for run_ in ints['runs']:
            if 'model' not in run_ or 'right' not in run_:
                continue
            L.append(f"| {run_['model']} (K = {run_.get('n_components')}) | "
                     f"{run_['right']}/{run_['n']} | {pct(run_['commit_fraction_mean'])} | "
                     f"{run_['flange_to_partner_rms_cm_mean']:.1f} / "
                     f"{run_['offline_rms_cm_mean']:.1f} cm | "
                     f"{fmt(run_.get('flange_to_partner_from_onset_rms_cm_mean'), '.1f')} cm | "
                     f"{run_['flange_to_partner_end_cm_mean']:.1f} / "
                     f"{run_['offline_end_cm_mean']:.1f} cm | "
                     f"{run_['flange_to_person1_at_contact_cm_mean']:.1f} / "
                     f"{run_['people_at_contact_cm_mean']:.1f} cm; "
                     f"{fmt(run_.get('flange_to_person1_at_touch_cm_mean'), '.1f')} / "
                     f"{fmt(run_.get('people_at_touch_cm_mean'), '.1f')} cm | "
                     f"{run_.get('committed_after_contact', '-')}/{run_['n']} | "
                     f"{run_['tracking_rms_mrad_max']:.3f} mrad | "
                     f"{run_['refused_trajectories']} | {run_['points_beyond_limits']} |")
        L.append('')
    bench = [(k, R.get(k)) for k in ('train', 'train_scaling', 'estimator', 'sim', 'soak')]
    if any(b for _, b in bench):
        L += ['## Benchmarks (`bench/<name>.py`, one JSON object each, in '
              f'`{OUT.relative_to(ROOT)}`)', '']
        t = R.get('train')
        if t:
            L.append(f"- `train.py`: `mixture-ip train` on the 48 box-assembly bags: "
                     f"{t['train_s']:.2f} s (median of {len(t['runs']['train_s'])}; K = "
                     f"{t['chosen']}, floor {t['prior_scale']}), the straightforward loop "
                     f"{t.get('reference', {}).get('train_s', float('nan')):.2f} s, same "
                     f"selection: {t.get('same_selection')}.")
        ts = R.get('train_scaling')
        if ts:
            lay = ts['layout_10_dofs_36x300']
            L.append('- `train_scaling.py`: `mixture-ip train` on generated box assembly, seconds '
                     'by number of demonstrations: ' + ', '.join(
                         f'{n}: {s:.1f}' for n, s in zip(ts['sizes'], ts['seconds']))
                     + f" (time ~ N^{ts['exponent']:.2f}); 36 demonstrations of 10 DOFs x 300 "
                     f"samples {lay['seconds']:.1f} s. Stages at N = {ts['sizes'][-1]}: "
                     + ', '.join(f'{k} {v:.1f} s' for k, v in ts['stages'][-1].items()) + '.'
                     + (' Phase chosen by held-out prediction: ' + ', '.join(
                         f'{n}: {p}' for n, p in zip(ts['sizes'], ts['phase'])) + '.'
                        if 'phase' in ts else ''))
        e = R.get('estimator')
        if e:
            L.append(f"- `estimator.py`: one observation absorbed by the online estimator "
                     f"({e['hypotheses']} hypotheses, observed weights of dimension "
                     f"{e['observed_weight_dim']}): median {e['update_us_median']:.0f} us, 99th "
                     f"percentile {e['update_us_p99']:.0f} us ({e['pruned']['update_us_median']:.0f}"
                     f" us once unlikely hypotheses are pruned"
                     + (f"; {e['switching']['update_us_median']:.0f} us with changes of mind "
                        f"({e['switching']['ratio_to_exact']:.2f}x)" if 'switching' in e else '')
                     + f"); batch conditioning after 500 observations "
                     f"{e['naive_us_m500'] / 1e6:.1f} s.")
        s = R.get('sim')
        if s:
            L.append(f"- `sim.py`: MuJoCo + Pinocchio controller {s['step_us_total']:.1f} us per "
                     f"1 kHz step ({s['realtime_factor']:.0f}x real time); the sim node "
                     f"{s['node_realtime_factor']:.1f}x, its executable "
                     f"{s['executable_realtime_factor']:.1f}x, joint states every "
                     f"{s['node_joint_state_max_gap_s'] * 1e3:.0f} ms of simulated time at most.")
        k = R.get('soak')
        if k:
            L.append(f"- `soak.py`: {k['soak_s'] / 60:.0f} min of {k['rate_hz']:.0f} Hz mocap with "
                     f"{k['load']} busy processes beside it: {k['commits_on_reaches']}/"
                     f"{k['reaches']} reaches committed, {k['commits_on_returns']} commitments on "
                     f"returns and {k['commits_on_transitions']} on transitions, "
                     f"{k['trajectories']} trajectories, {k['points_beyond_limits']} points beyond "
                     f"limits; estimator memory {k['rss_mb_start_estimator']:.0f} -> "
                     f"{k['rss_mb_end_estimator']:.0f} MB.")
        L.append('')
    return '\n'.join(L)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--reuse', action='store_true', help='keep the JSON already there')
    ap.add_argument('--only', default=None,
                    help='comma-separated job names to (re)run; the others are kept (and run '
                         'where their JSON is missing)')
    args = ap.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    todo = jobs()
    only = set(args.only.split(',')) if args.only else None
    R = {}
    for name, (command, target) in todo.items():
        path = OUT / f'{name}.json'
        # A job named by --only runs even when --reuse would keep its JSON; a job whose JSON
        # is not there runs in any case, so the page never lacks a part.
        kept = path.is_file() and (name not in only if only is not None else args.reuse)
        R[name] = json.loads(path.read_text()) if kept else run(name, command, target)
    (ROOT / 'docs' / 'results.md').write_text(page(R) + '\n')
    print(json.dumps({'written': 'docs/results.md', 'parts': sorted(R)}))


if __name__ == '__main__':
    main()
