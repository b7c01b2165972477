"""How the online planner (estimation.planner) commits, replans and plans: its settings,
validated."""

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class PlannerSettings:
    """How the planner commits, replans and plans. ``replan_period`` is 1 / the replan rate;
    ``backlog_slice``: held samples conditioned on per call after an onset;
    ``max_clock_offset`` (s, 0 = no check): a plan resting on an observation stamped further
    than this from the caller's clock is not sent (the observations are on another clock, and
    the controller would wait for a start years away). ``hedge``: before the commit, once the
    commit waits on confidence alone, send the plan with the component marginalised too
    (estimation.plans.build_plan's ``hedged``), so that the robot is under way when the
    interaction is recognised. ``max_joint_state_age``, ``max_wrist_silence`` (s, 0 = no
    check): when the arm's state or the wrist stream is too old (estimation.stale_inputs).
    ``delivery_margin`` (s): a plan reaches the controller this long after the present it was
    timed from, at most (the node clock steps with /clock, every 10 ms of the sim, and a plan
    that catches up takes some ms to compute): where the arm catches up, its first point is
    one it still reaches within its limits from then (estimation.plans.build_plan's
    ``margin``), so that the controller need not re-time it. ``horizon`` (s, 0 = none): each
    plan sent follows the path this long past the present, then stops at rest within the joint
    limits (estimation.horizon); the next replan extends it, so an arm left alone stops (one
    shorter than a replan period and the command's delivery stops the arm between plans)."""

    confidence_threshold: float = 0.9
    min_observations: int = 3
    n_points: int = 25
    lookahead: float = 0.1
    settle_time: float = 0.5
    hold_window: float = 2.5
    backlog_slice: int = 8
    replan_period: float = 0.1
    replan_on_observation: bool = True
    max_records: int = 1000
    max_clock_offset: float = 0.0
    hedge: bool = False
    max_joint_state_age: float = 0.0
    max_wrist_silence: float = 0.0
    delivery_margin: float = 0.05
    horizon: float = 0.0

    def __post_init__(self):
        def need(ok, what):
            if not ok:
                raise ValueError(what)
        need(0.0 < self.confidence_threshold <= 1.0,
             f'confidence_threshold must be in (0, 1], got {self.confidence_threshold}')
        for name, low in (('min_observations', 1), ('n_points', 2), ('backlog_slice', 1),
                          ('max_records', 1)):
            value = getattr(self, name)
            need(int(value) == value and value >= low,
                 f'{name} must be an integer >= {low}, got {value}')
        need(np.isfinite(self.lookahead) and self.lookahead >= 0,
             f'lookahead must be >= 0 s, got {self.lookahead}')
        for name in ('settle_time', 'hold_window', 'replan_period'):
            value = getattr(self, name)
            need(np.isfinite(value) and value > 0, f'{name} must be > 0 s, got {value}')
        for name in ('max_clock_offset', 'max_joint_state_age', 'max_wrist_silence',
                     'delivery_margin', 'horizon'):
            value = getattr(self, name)
            need(np.isfinite(value) and value >= 0, f'{name} must be >= 0 s, got {value}')
