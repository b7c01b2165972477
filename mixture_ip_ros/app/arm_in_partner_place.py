"""`mixture-ip train --csv DIR --arm-in-partner-place FILE`: recordings of two people become an
arm's demonstrations. The observed columns are person 1's hand, the controlled ones the
partner's (x, y, z each, in m, cm or mm); the arm takes the partner's place as FILE places it
(robot.partner_place, config/partner_placement.yaml). The model then observes person 1's hand
in the robot's base frame and controls the arm's joints, as a model trained from bags does, so
the nodes run it on that arm; the model file records the placement (metadata ``extra``
``partner_place``), with where person 1 must stand in the mocap frame.
"""

import logging

import numpy as np

from mixture_ip_ros.core.demonstration import Demonstration, Layout
from mixture_ip_ros.robot import partner_place

logger = logging.getLogger(__name__)

# Metres per unit of a hand position ('' = not given: metres).
_METRES = {'': 1.0, 'm': 1.0, 'cm': 0.01, 'mm': 0.001}


def check_layout(layout: Layout):
    """ValueError unless ``layout`` names two hands: 3 observed and 3 controlled columns, each
    in a unit of length."""
    for agent, who in (('observed', "person 1's hand"), ('controlled', "the partner's hand")):
        names, units = getattr(layout, agent), getattr(layout, agent + '_units')
        if len(names) != 3:
            raise ValueError(f'the {agent} columns are {who}: 3 of them (x, y, z), got '
                             f'{len(names)} ({", ".join(names) or "none"})')
        bad = [u for u in units if u not in _METRES]
        if bad:
            raise ValueError(f'the {agent} columns are {who}, a position: in m, cm or mm, not '
                             f'{bad[0]!r}')


def options_problem(placement_file, layout, fixed) -> str:
    """What makes `train --arm-in-partner-place` impossible, in one line (None: nothing):
    ``layout`` the --csv columns (None without --csv), ``fixed`` the options given that the
    placement sets. A placement file that cannot be read raises ValueError (bad input, found
    before the recordings are read)."""
    if layout is None:
        return ("--arm-in-partner-place: for --csv DIR only (its columns are the two people's "
                'hands)')
    if fixed:
        return (f'{", ".join(fixed)}: not with --arm-in-partner-place (the arm stands where the '
                "placement puts it, and observes in the robot's base frame)")
    try:
        check_layout(layout)
    except ValueError as error:
        return f'--arm-in-partner-place: {error}'
    partner_place.load_placement(placement_file)
    return None


def arm_demonstrations(demos, layout: Layout, placement_file, robot) -> tuple:
    """The recordings ``demos`` (with ``layout``'s columns) with the arm ``robot`` in the
    partner's place that ``placement_file`` sets: (the arm's demonstrations, the model file's
    ``extra`` record of the placement). Logs the reach scale, where person 1 stands, and how
    closely the flange follows the partner's hand."""
    check_layout(layout)
    config = partner_place.load_placement(placement_file)
    metres = [np.array([_METRES[u] for u in units])
              for units in (layout.observed_units, layout.controlled_units)]
    in_metres = [Demonstration(d.t, d.observed * metres[0], d.controlled * metres[1],
                               label=d.label, name=d.name) for d in demos]
    place, made, lags = partner_place.arm_demonstrations(robot, config, in_metres)
    record = place.metadata()
    lag = np.concatenate(lags)
    lag = lag[np.isfinite(lag)]
    origin, yaw = record['person1_in_world']['xyz'], record['person1_in_world']['yaw']
    logger.info('%s in the partner\'s place (%s): reach scale %.3f; person 1\'s recording '
                'frame lies in the mocap frame at (%.2f, %.2f, %.2f) m, its x axis at %.0f deg '
                '(a person moving there as recorded is where the model expects them); the '
                'flange follows the partner\'s hand within %.1f cm (median), %.1f cm (95th '
                'percentile)',
                place.robot.name, placement_file, place.placement.scale, *origin,
                np.degrees(yaw), 100 * np.median(lag), 100 * np.percentile(lag, 95))
    record['flange_to_partner_cm'] = {'median': float(100 * np.median(lag)),
                                      'p95': float(100 * np.percentile(lag, 95))}
    return made, {'partner_place': record}
