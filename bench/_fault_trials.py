"""The trials of bench/faults.py (and test/test_faults.py): a kill with its restart and the
next interaction, the bags with dropped wrist messages, a stray publisher. Each returns its
rows (plain values for JSON); a run that cannot go on is a row with ``failure``."""

from pathlib import Path
import queue
import subprocess
import sys
import threading
import traceback

import numpy as np

from bench._fault_loop import (ROOT, FaultRunError, NodeSet, after_kill, count,
                               estimator_outcome, human_end, interaction, latest, speeds,
                               stopping_time, REST_SPEED)
from mixture_ip_ros.core.share import config_path
from mixture_ip_ros.robot.kinematics import RobotKinematics

KILLED = ('estimator_node', 'observer_node', 'sim_node')
# When the kill comes: 0.3 s after the first plan arrived; halfway from it to the end of the
# movement (the bag's annotated end, dated from the observer's onset, plus the estimator's
# settle_time); and, after that, once the arm slows down to SLOWING of its peak speed since
# the first plan (near the end of its movement, which the arm reaches before the person's).
PHASES = ('first_plan', 'mid', 'late')
SLOWING = 0.3
AFTER_FIRST_PLAN = 0.3      # s
# How long the arm is watched after a kill (simulated s) at least: the observer's kill leaves
# the estimator alive, which ends the interaction after max_wrist_silence (2.5 s).
WATCH = {'estimator_node': 2.0, 'observer_node': 3.5}
SIM_DEAD_WATCH = 3.0        # wall s the dead sim is watched
DROP_SHARES = (0.0, 0.1, 0.2, 0.3)
MAX_BURST = 1.0             # s
STRAY_COMMANDS = 10


def _settle_time() -> float:
    import yaml
    with open(config_path('estimator.yaml')) as f:
        return float(yaml.safe_load(f)['estimator_node']['ros__parameters']['settle_time'])


def kill_time(phase: str, t_plan: float, t_end: float, settle: float) -> float:
    """When to kill (simulated s) from the first plan's arrival and the movement's end; for
    ``late``, the earliest time (then :func:`slowing`)."""
    if phase == 'first_plan':
        return t_plan + AFTER_FIRST_PLAN
    return t_plan + max(0.5 * (t_end + settle - t_plan), 0.05)


def slowing(p, since: int) -> bool:
    """The arm at most SLOWING of its peak speed since joint state ``since``."""
    s = speeds(p.qd[since:])
    return len(s) > 0 and s[-1] <= SLOWING * s.max()


def rested_for(p, seconds: float) -> bool:
    """The arm slower than REST_SPEED on every joint state of the last ``seconds``."""
    if not p.t:
        return False
    i = int(np.searchsorted(p.t, p.t[-1] - seconds))
    return i < len(p.t) - 1 and bool(np.all(speeds(p.qd[i:]) < REST_SPEED))


def _first_plan(p, since: int):
    return next((c for c in p.plans[since:] if not c['empty'] and not c['stray']), None)


def _lines(p, since: int, node: str, limit: int = 6) -> list:
    return [line['msg'][:160] for line in p.lines[since:] if line['node'] == node][:limit]


def _plans_after(p, since: int, kill_ns: int) -> dict:
    if any(c['sent_ns'] <= 0 for c in p.plans):
        raise FaultRunError('the middleware gave plans no source timestamp')
    after = [c for c in p.plans[since:] if not c['stray'] and c['sent_ns'] > kill_ns]
    return {'plans_after_kill': sum(not c['empty'] for c in after),
            'holds_after_kill': sum(c['empty'] for c in after)}


def kill_trial(model, domain, bag, next_bag, labels, node, phase, log_dir) -> dict:
    """One kill of ``node`` at ``phase`` of ``bag``'s interaction, its restart and ``next_bag``."""
    row = {'node': node, 'phase': phase, 'bag': bag.name, 'next_bag': next_bag.name,
           'log_dir': str(log_dir)}
    kin = RobotKinematics()
    ns = NodeSet(model, domain, log_dir)
    p = ns.probe
    try:
        ns.start()
        # the sim's counts before the interaction, while no command is on its way
        since = p.seq
        ns.wait(lambda: latest(p.diagnostics, 'sim_node', since) is not None, 10.0,
                'a sim report')
        sim_start = latest(p.diagnostics, 'sim_node')
        plans0, events0 = len(p.plans), len(p.events)
        ns.play(bag)
        ns.wait(lambda: _first_plan(p, plans0) is not None, 60.0, 'the first plan')
        t_plan, start = _first_plan(p, plans0)['t'], _first_plan(p, plans0)['seq']
        onset = next(e['stamp'] for e in p.events[events0:] if e['kind'] == 'onset')
        target = kill_time(phase, t_plan, human_end(bag, onset), _settle_time())
        ns.wait_sim(target)
        if phase == 'late':
            ns.wait(lambda: slowing(p, start), 60.0, 'the arm slowing down')
        seq, plans_kill, lines_kill = p.seq, len(p.plans), len(p.lines)
        sim_before = latest(p.diagnostics, 'sim_node')
        est_before = latest(p.diagnostics, 'estimator_node')
        t_kill = ns.kill(node)
        row.update(t_first_plan=t_plan, t_kill=t_kill, kill_after_first_plan_s=t_kill - t_plan,
                   stopping_time_s=stopping_time(p.qd[seq - 1], kin))
        if node == 'sim_node':
            row.update(_sim_killed(ns, seq, plans_kill, lines_kill, t_kill, est_before))
        else:
            window = WATCH[node]
            ns.wait(lambda: p.now >= t_kill + window and rested_for(p, 0.5)
                    or p.now >= t_kill + 10.0, 60.0, 'the arm watched after the kill')
            row.update(after_kill(p.t[seq - 1:], p.q[seq - 1:], p.qd[seq - 1:], t_kill, kin))
            row.update(_plans_after(p, plans_kill, ns.kill_ns))
            # commands the sim took after the kill: its count since its report before the
            # interaction, less the plans sent before the kill (a report during the
            # interaction can count a plan the probe has yet to receive)
            ns.wait(lambda: latest(p.diagnostics, 'sim_node', p.seq) is not None, 10.0,
                    'a sim report')
            sim_after = latest(p.diagnostics, 'sim_node')
            before_kill = sum(not c['empty'] and not c['stray'] and c['seq'] >= sim_start['seq']
                              and c['sent_ns'] <= ns.kill_ns for c in p.plans)
            row['sim_accepted_after_kill'] = (count(sim_after, 'commands_accepted')
                                              - count(sim_start, 'commands_accepted')
                                              - before_kill)
            row['sim_holds_source_lost'] = (count(sim_after, 'holds_source_lost')
                                            - count(sim_before, 'holds_source_lost'))
            row['sim_liveliness_lapses'] = (count(sim_after, 'liveliness_lapses')
                                            - count(sim_before, 'liveliness_lapses'))
            if node == 'observer_node':
                est = latest(p.diagnostics, 'estimator_node')
                row['estimator_ends_wrist_silent'] = (count(est, 'ends_wrist_silent')
                                                      - count(est_before, 'ends_wrist_silent'))
            row['estimator_lines_after_kill'] = _lines(p, lines_kill, 'estimator_node')
            row['sim_lines_after_kill'] = _lines(p, lines_kill, 'sim_node')
            ns.wait(ns.player_done, 60.0, 'the first bag played')
            ns.restart(node)
        row['next'] = interaction(ns, next_bag, labels[next_bag.name])
    except Exception as exc:
        row['failure'] = f'{type(exc).__name__}: {exc}'
        if not isinstance(exc, FaultRunError):
            row['traceback'] = traceback.format_exc()[-1500:]
    finally:
        row['exit_codes'] = ns.close()
        row['errors'] = ns.errors()
    return row


def _sim_killed(ns, seq, plans_kill, lines_kill, t_kill, est_before) -> dict:
    """The sim dead: what comes in SIM_DEAD_WATCH wall s; its restart (a clock from 0) and
    what the old bag player and the other nodes do until the old simulated time is passed."""
    p = ns.probe
    ns.watch_wall(SIM_DEAD_WATCH)
    out = {'joint_states_while_dead': p.seq - seq, **_plans_after(p, plans_kill, ns.kill_ns),
           'estimator_lines_while_dead': _lines(p, lines_kill, 'estimator_node'),
           'observer_lines_while_dead': _lines(p, lines_kill, 'observer_node')}
    est_dead = latest(p.diagnostics, 'estimator_node')
    out['estimator_reports_while_dead'] = sum(d['seq'] >= seq for d in
                                              p.diagnostics['estimator_node'])
    lines_restart, events_restart, plans_restart = len(p.lines), len(p.events), len(p.plans)
    restart = p.seq
    ns.restart('sim_node')
    out['first_sim_time_seen_after_restart'] = p.t[restart]
    out['old_player_alive_after_restart'] = not ns.player_done()
    # the old player paces on the old simulated time: does it go on once the new clock passes it?
    ns.wait(lambda: p.now > t_kill + 1.5 or ns.player_done(), 60.0,
            'the new clock past the old time', required=False)
    out['old_player_done_after_clock_passed'] = ns.player_done()
    out['events_after_restart'] = [e['kind'] for e in p.events[events_restart:]]
    out['plans_after_restart_before_next'] = sum(not c['empty'] for c in p.plans[plans_restart:])
    ns.stop_player()
    ns.wait(lambda: latest(p.diagnostics, 'estimator_node', p.seq) is not None, 10.0,
            'an estimator report')
    est = latest(p.diagnostics, 'estimator_node')
    out['estimator_ends_clock_reset'] = (count(est, 'ends_clock_reset')
                                         - count(est_before, 'ends_clock_reset'))
    out['estimator_stale_joint_states'] = (count(est, 'stale_joint_states')
                                           - count(est_before, 'stale_joint_states'))
    out['estimator_state_while_dead'] = est_dead and est_dead.get('state')
    out['estimator_lines_after_restart'] = _lines(p, lines_restart, 'estimator_node')
    out['observer_lines_after_restart'] = _lines(p, lines_restart, 'observer_node')
    return out


# -- dropped wrist messages ------------------------------------------------------------------
def burst_mask(n: int, share: float, max_burst: int, rng) -> np.ndarray:
    """Which of ``n`` messages are kept: round(share n) dropped in bursts of 1 to ``max_burst``
    messages, each burst between kept ones (so none is longer), the first and last kept."""
    keep = np.ones(n, dtype=bool)
    need = int(round(share * n))
    for _ in range(100_000):
        if need <= 0:
            break
        length = min(int(rng.integers(1, max_burst + 1)), need, n - 2)
        start = int(rng.integers(1, n - length))
        if keep[start - 1:start + length + 1].all():
            keep[start:start + length] = False
            need -= length
    return keep


def dropped_bag(src: Path, dst: Path, share: float, rng) -> dict:
    """``src`` with ``share`` of its wrist messages dropped in bursts up to MAX_BURST s, written
    to ``dst`` with the package's bag writer (the label and annotations kept) and read back."""
    from mixture_ip_ros.io.bags import LABEL_KEY, read_bag, write_demonstration_bag
    raw = read_bag(src)
    period = float(np.median(np.diff(raw.wrist_t)))
    keep = burst_mask(len(raw.wrist_t), share, int(round(MAX_BURST / period)), rng)
    write_demonstration_bag(
        dst, raw.wrist_t[keep], raw.wrist_xyz[keep], raw.joint_t, raw.joint_q,
        label=raw.label, frame_id=raw.wrist_frame, joint_names=raw.joint_names,
        wrist_quat=raw.wrist_quat[keep], joint_qd=raw.joint_qd, start_time_ns=raw.start_time_ns,
        custom_data={k: v for k, v in (raw.custom_data or {}).items() if k != LABEL_KEY})
    back = read_bag(dst)
    edges = np.diff(np.concatenate([[0], (~keep).astype(int), [0]]))
    bursts = np.flatnonzero(edges < 0) - np.flatnonzero(edges > 0)
    return {'kept': int(len(back.wrist_t)), 'of': int(len(keep)),
            'bursts': int(len(bursts)),
            'longest_burst_s': float(bursts.max() * period) if len(bursts) else 0.0}


def drop_run(model, domain, bags, labels, share, seed, root) -> list:
    """The bags (their wrist thinned by ``share``) through one fresh set of nodes, in order."""
    rows = []
    folder = root / f'drop_{round(100 * share)}'
    folder.mkdir(parents=True, exist_ok=True)
    played = []
    for i, bag in enumerate(bags):
        if share == 0.0:
            played.append((bag, {'kept': None}))
            continue
        rng = np.random.default_rng([seed, i, round(100 * share)])
        played.append((folder / bag.name, dropped_bag(bag, folder / bag.name, share, rng)))
    ns = NodeSet(model, domain, folder / 'logs')
    try:
        ns.start()
        for (path, dropped), bag in zip(played, bags):
            try:
                rows.append({**interaction(ns, path, labels[bag.name], target_bag=bag),
                             'dropped': dropped})
            except FaultRunError as exc:
                rows.append({'bag': bag.name, 'failure': str(exc)})
                break
    except FaultRunError as exc:
        rows.append({'failure': str(exc)})
    finally:
        codes = ns.close()
        errors = ns.errors()
    for row in rows:
        row['exit_codes'], row['errors'] = codes, errors
    return rows


# -- a stray publisher -------------------------------------------------------------------------
class _Stray:
    """bench/_fault_stray.py in a process of its own; its lines read in a thread."""

    def __init__(self, env):
        self.proc = subprocess.Popen([sys.executable, str(ROOT / 'bench' / '_fault_stray.py')],
                                     env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True)
        self.lines = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self):
        for line in self.proc.stdout:
            self.lines.put(line.strip())

    def say(self, text: str) -> None:
        self.proc.stdin.write(text + '\n')
        self.proc.stdin.flush()

    def heard(self, word: str):
        """A predicate for NodeSet.wait: the stray printed a line starting with ``word``."""
        seen = []

        def check():
            while not self.lines.empty():
                seen.append(self.lines.get())
            return any(s.startswith(word) for s in seen)
        return check

    def close(self) -> int:
        if self.proc.poll() is None:
            try:
                self.say('quit')
                return self.proc.wait(timeout=20)
            except (OSError, subprocess.TimeoutExpired):
                self.proc.kill()
        return self.proc.wait()


def stray_trial(model, domain, bag, labels, log_dir, n: int = STRAY_COMMANDS) -> dict:
    """A stray publisher joins 0.3 s after the first plan, sends ``n`` commands, stays two sim
    reports more, then leaves. ``accepted_while_stray``: the sim's commands taken between its
    first and last report with the stray on the topic (every stray command came between)."""
    row = {'bag': bag.name, 'stray_sent': n, 'log_dir': str(log_dir)}
    ns = NodeSet(model, domain, log_dir)
    p = ns.probe
    stray = None
    try:
        ns.start()
        stray = _Stray(ns.children.env)
        ns.wait(stray.heard('ready'), 60.0, 'the stray process')
        plans0, lines0 = len(p.plans), len(p.lines)
        ns.play(bag)
        ns.wait(lambda: _first_plan(p, plans0) is not None, 60.0, 'the first plan')
        ns.wait_sim(_first_plan(p, plans0)['t'] + AFTER_FIRST_PLAN)
        stray.say('go 2')            # the sim's subscription and the probe's
        ns.wait(stray.heard('matched'), 30.0, 'the stray matched')

        def refusing(since):
            d = latest(p.diagnostics, 'sim_node', since)
            return d is not None and d.get('refusing', '') != ''
        ns.wait(lambda: refusing(p.seq), 10.0, 'the sim refusing')
        first = latest(p.diagnostics, 'sim_node')
        stray.say(f'send {n}')
        ns.wait(stray.heard('sent'), 30.0, 'the stray sending')
        sent_seq = p.seq
        ns.wait(lambda: len([d for d in p.diagnostics['sim_node'] if d['seq'] > sent_seq]) >= 2,
                10.0, 'two sim reports after the stray commands')
        last = latest(p.diagnostics, 'sim_node')
        row['refusing_at_last_report'] = last.get('refusing')
        row['exit_code_stray'] = stray.close()
        ns.wait(lambda: latest(p.diagnostics, 'sim_node', p.seq) is not None
                and not refusing(p.seq - 1), 30.0, 'the sim taking commands again',
                required=False)
        window = [c for c in p.plans[plans0:] if first['seq'] <= c['seq'] <= last['seq']]
        row.update(
            stray_received_by_probe=sum(c['stray'] for c in p.plans[plans0:]),
            accepted_while_stray=count(last, 'commands_accepted')
            - count(first, 'commands_accepted'),
            refused_while_stray=count(last, 'commands_refused_sender')
            - count(first, 'commands_refused_sender'),
            commands_in_window=len([c for c in window if not c['empty']]),
            estimator_plans_in_window=len([c for c in window if not c['empty']
                                           and not c['stray']]),
            refused_total=count(last, 'commands_refused_sender'),
            other_publishers=count(last, 'other_publishers'),
            sim_warnings=[line['msg'][:160] for line in p.lines[lines0:]
                          if line['node'] == 'sim_node' and line['level'] >= 30][:4])
        ns.wait(ns.player_done, 60.0, 'the bag played')
        ns.wait(lambda: estimator_outcome(p.lines[lines0:])['result'] is not None, 15.0,
                'the estimator reporting', required=False)
        row['outcome'] = estimator_outcome(p.lines[lines0:])
        row['accepted_after_stray_left'] = (count(latest(p.diagnostics, 'sim_node'),
                                                  'commands_accepted')
                                            - count(last, 'commands_accepted'))
    except Exception as exc:
        row['failure'] = f'{type(exc).__name__}: {exc}'
        if not isinstance(exc, FaultRunError):
            row['traceback'] = traceback.format_exc()[-1500:]
    finally:
        if stray is not None:
            stray.close()
        row['exit_codes'] = ns.close()
        row['errors'] = ns.errors()
    return row


