"""What estimator_node reports on /diagnostics: the planner's state, its counts and the node's
latencies as one status, WARN while problems are new."""

from diagnostic_msgs.msg import DiagnosticArray

from mixture_ip_ros.nodes.diagnostics import OK, WARN, diagnostic_array

DIAGNOSTIC_NAME = 'estimator_node: estimation'


def estimation_values(planner, latency, plan_latency, events) -> dict:
    """{key: value} of the status: the interaction in progress (``planner.current``), the
    planner's totals, the latencies (estimation.records.LatencyStats: ``latency`` of a used
    observation, ``plan_latency`` of a trajectory sent) and the unknown events counted."""
    counts = planner.counts
    rec = planner.current
    return {
        'state': planner.state,
        'interactions': len(planner.interactions),
        'component': rec and rec.component,
        'label': rec and rec.label,
        'confidence': rec and rec.confidence,
        'alpha': rec and rec.alpha,
        'phase': rec and rec.phase,
        'commit_phase': rec and rec.commit_phase,
        'switches': len(rec.switches) if rec else 0,
        'observations_received': counts.received,
        'observations_used': counts.used,
        'observations_skipped': counts.skipped,
        'observations_held': planner.n_held,
        'observations_backlog': planner.n_backlog,
        'interaction_observations_used': rec and rec.n_observations,
        **{f'rejected_{k}': v for k, v in counts.rejected.items()},
        'update_latency_last_us': round(latency.last_us, 1),
        'update_latency_mean_us': round(latency.mean_us, 1),
        'update_latency_max_us': round(latency.max_us, 1),
        'plan_latency_last_us': round(plan_latency.last_us, 1),
        'plan_latency_mean_us': round(plan_latency.mean_us, 1),
        'plan_latency_max_us': round(plan_latency.max_us, 1),
        'plans_sent': counts.plans_sent,
        'holds_unexplained': counts.holds,
        'stale_joint_states': counts.stale_joint_states,
        'ends_wrist_silent': counts.silent_ends,
        'ends_clock_reset': counts.clock_resets,
        'unexplained': rec and rec.unexplained,
        'plans_time_scaled': counts.plans_time_scaled,
        'plans_uncut': counts.plans_uncut,
        **{f'plans_refused_{k}': v for k, v in counts.plan_refusals.items()},
        'events_unknown': events['unknown'],
    }


class EstimationDiagnostics:
    """estimator_node's /diagnostics messages. It remembers the problem totals of the previous
    message: WARN while problems are new (since then); the totals stay in the values."""

    def __init__(self):
        self._seen = (0, 0)     # observations rejected, plans refused

    def message(self, stamp, planner, latency, plan_latency, events) -> DiagnosticArray:
        values = estimation_values(planner, latency, plan_latency, events)
        counts = planner.counts
        new_rejected = counts.n_rejected - self._seen[0]
        new_failures = counts.plan_failures - self._seen[1]
        self._seen = (counts.n_rejected, counts.plan_failures)
        if new_failures:
            level, message = WARN, f'{planner.state}; {new_failures} plans refused'
        elif new_rejected:
            level, message = WARN, f'{planner.state}; {new_rejected} observations rejected'
        else:
            level, message = OK, planner.state
        return diagnostic_array(stamp, DIAGNOSTIC_NAME, level, message, values)


def sent_lines(step, rec, label) -> list:
    """The lines estimator_node logs when the planner's ``step`` sent a plan: the commit, a
    switch of component; ``rec``: the interaction, ``label(k)``: ' (its label)'."""
    plan, lines = step.plan, []
    if step.committed_now:
        lines.append(f'committed to component {plan.component}{label(plan.component)} '
                     f'(p = {rec.confidence:.3f}) at phase {rec.commit_phase:.3f} after '
                     f'{rec.commit_observations} observations, alpha* = {plan.alpha:.3f}/s')
    if step.switched_from is not None:
        lines.append(f'switching from component {step.switched_from}'
                     f'{label(step.switched_from)} to {plan.component}{label(plan.component)} '
                     f'at phase {rec.phase:.3f}')
    return lines


def finished_report(rec, settings, label: str) -> tuple:
    """(whether it is a warning, the line) that estimator_node logs when the interaction
    ``rec`` (estimation.records.Interaction) ends; ``label``: ' (its label)' of the component or
    ''."""
    if not rec.committed and rec.unexplained is not None:
        return True, (f'interaction ended uncommitted, the model does not explain it '
                      f'({rec.unexplained}): robot not moved')
    if not rec.committed:
        confidence = rec.confidence if rec.confidence is not None else float('nan')
        return True, (f'interaction ended without a confident component (p(k*) = '
                      f'{confidence:.3f} < {settings.confidence_threshold} or fewer than '
                      f'{settings.min_observations} observations): robot not moved')
    return False, (f'interaction done: component {rec.component}{label}, '
                   f'alpha* = {rec.alpha:.3f}/s, committed at phase {rec.commit_phase:.3f}, '
                   f'{rec.n_observations} observations used, {rec.plans} plans, '
                   f'{len(rec.switches)} switches')
