"""What one closed-loop interaction leaves behind: the data for reports, plots and videos."""

from dataclasses import dataclass, field
from typing import Optional

import numpy as np


@dataclass
class InteractionRecord:
    """Time series of one replayed interaction, all in the robot base frame, times in seconds
    of simulated time.

    ``t``/``q``: robot joint positions (n, 7) sampled from /joint_states; ``flange`` (n, 3) the
    robot hand (tool0) position at the same times;
    ``wrist_t``/``wrist``: the human wrist as the observer published it (m, 3);
    ``posterior_t``/``posterior``: p(k | D) (r, K), ``phase`` (r,) and ``alpha`` (r,) as the
    estimator published them. Event times may be None when the event did not happen.
    """

    name: str
    true_pattern: Optional[str]
    component_labels: list
    t: np.ndarray
    q: np.ndarray
    flange: np.ndarray
    wrist_t: np.ndarray
    wrist: np.ndarray
    posterior_t: np.ndarray
    posterior: np.ndarray
    phase: np.ndarray
    alpha: np.ndarray
    onset_time: Optional[float] = None
    commit_time: Optional[float] = None
    end_time: Optional[float] = None
    chosen_pattern: Optional[str] = None
    commit_fraction: Optional[float] = None
    target: Optional[np.ndarray] = None         # where the robot hand should end (base frame)
    extra: dict = field(default_factory=dict)
