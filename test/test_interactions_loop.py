"""The robot takes a person's part, in-process: one held-out NuiSI v2 recording per interaction
replayed from rosbag2 bags through the real nodes (bag_player -> observer -> estimator -> sim)
on simulated time, the iiwa in the partner's place.

The model is the demo's: trained without labels on the retargeted training split, K chosen
(it finds the four interactions; labels only name its components). The shortest held-out
recording of each interaction is replayed at twice real time (the nodes run on simulated time,
so only the wall-clock time changes): about 35 s of replay.
"""

import numpy as np
import pytest

from conftest import private_domain_id
from mixture_ip_ros.io.cache import cache_dir
from mixture_ip_ros.scenarios import nuisi

pytestmark = pytest.mark.filterwarnings('ignore::DeprecationWarning')


@pytest.fixture(scope='module')
def report(tmp_path_factory):
    if not (cache_dir() / 'nuisi' / nuisi.VERSIONS['v2'].file).is_file():
        pytest.skip('NuiSI is not in the user cache (./dev seeds it from ../shared/data/nuisi)')
    from mixture_ip_ros.app import interactions as app
    root = tmp_path_factory.mktemp('interactions')
    scene, model_path, info = app.prepare_interactions_demo(root / 'bags', root, 'iiwa14')
    shortest = {}
    for r in nuisi.recordings('v2', 'test'):
        if r.label not in shortest or len(r.t) < len(shortest[r.label].t):
            shortest[r.label] = r
    _, report = app.replay(scene, model_path, info, root / 'bags',
                           names=sorted(r.name for r in shortest.values()),
                           real_time_factor=2.0, domain_id=private_domain_id())
    return report


@pytest.mark.decision
def test_each_interaction_is_recognised_before_its_end(report):
    # Four interactions, found without labels: K = 4, or more where one is done in ways the
    # recordings reproduce, each component still one interaction. Compared by their
    # time-warped paths (core.pattern_space) the 33 training recordings make K = 6: waving
    # (4 + 5) and the parachute fist bump (4 + 3) each in two groups, every subsample pair
    # agreeing; at equal phases K = 5, the waving alone in two.
    assert report['n_components'] in (4, 5, 6)
    rows = report['interactions']
    assert sorted(r['true_pattern'] for r in rows) == sorted(nuisi.VERSIONS['v2'].interactions)
    for r in rows:
        assert r['chosen_pattern'] == r['true_pattern'], r['name']
        assert r['commit_fraction'] is not None and 0 < r['commit_fraction'] < 1, r['name']


def test_the_arm_answers_as_the_partner_did_within_its_limits(report):
    """The arm ends where the partner's hand did, tracks its commands, and never commands a
    point beyond its limits. (Between commitment and the end the loop's error also holds the
    time the arm needs from its rest to the partner's hand once it commits, which the offline
    prediction does not: docs/results.md reports both.)"""
    for r in report['interactions']:
        # The shortest waving recording ends farthest: 14.1 cm with eq. 14's weights, 15.2 and
        # 15.8 with the smoothed ones (K = 5 and 4), the other three within 10 cm.
        assert r['flange_to_partner_end_cm'] < 17.0, r['name']
        assert np.isfinite(r['flange_to_partner_rms_cm']) and np.isfinite(r['offline_rms_cm'])
        # at the recorded contact: measured (issue 32 sets its aim), the people closer there
        # than anywhere else (a wave's people stay half a metre apart)
        assert 0 < r['people_at_contact_cm'] < 100, r['name']
        assert np.isfinite(r['flange_to_person1_at_contact_cm']), r['name']
        # when the arm committed against when the people's hands met (it starts from its rest
        # there: a handshake met 1.5 s after its onset is over before the arm arrives)
        assert np.isfinite(r['commit_before_contact_s']), r['name']
        assert r['tracking_rms_mrad'] < 0.5, r['name']
        assert r['points_beyond_limits'] == 0 and r['non_finite_commands'] == 0, r['name']
        assert r['refused_trajectories'] <= 1, r['name']    # a plan late under load, at most
    assert report['committed_after_contact'] == sum(r['commit_before_contact_s'] < 0
                                                    for r in report['interactions'])
    # the scenario hedges (config/interactions.yaml): the arm set off before it committed
    assert sum(r['hedged_plans'] for r in report['interactions']) > 0
