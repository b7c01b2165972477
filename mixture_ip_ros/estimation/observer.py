"""What the observer node decides, without ROS: which mocap poses are usable, the wrist in the
robot base frame, and the interaction's onset, end and gaps.

A pose is used when the message is well formed, its stamp is within ``max_clock_offset`` of the
caller's clock (``now_ns``, the node clock: another clock, a pose stamped years ahead, would
otherwise take over the stream's time), its stamps increase, and it is a person's wrist at all
(estimation.pose_check.MotionPlausibility: in the workspace, moving and accelerating as a hand
can). Every used pose is forwarded as it comes, before the events it settles
(core.segmentation). The segmenter runs on the stamps' time (seconds since the first accepted
pose); silences are judged on the caller's clock, since mocap and node clocks may be offset.

A new stream (a bag replayed again or looping, a mocap clock reset) starts the observer afresh:
the interaction in progress ends at its last sample, and the segmentation, the motion checks and
the stream's time start again with the new stream's first pose, so that its onset is found as
the first one was and never dated into the old stream. A stream is new when

- its stamps jump back by more than ``new_stream_jump_back`` s at once (a replay with its
  recorded stamps; under simulated time the replayed /clock jumps back with them). When the
  clock is judged, the jump must agree with it: the pose is as near the clock as the old
  stream's last one was when it came, else it is a stray older pose and is dropped;
- its stamps keep going back by less (``restart_after_backwards`` in a row);
- at rest, it jumps to a place no hand reaches from the last accepted pose and stays there,
  ``new_stream_samples`` poses in a row that a hand could make (a looping replay whose stamps
  continue): held back meanwhile, they are the new stream's first poses. A jump that returns is
  a tracker's glitch, dropped as implausible. During a movement a jump is always taken for a
  glitch: the movement goes on.
"""

from dataclasses import dataclass, field
import math
from typing import List, Optional, Tuple

from mixture_ip_ros.core.frames import FrameTransform
from mixture_ip_ros.core.segmentation import Event, MotionSegmenter
from mixture_ip_ros.estimation.pose_check import (POSE_REJECT_REASONS, HumanLimits,
                                                  MotionPlausibility, check_pose)

# Consecutive poses off the clock after which the whole stream is taken to be on another one.
OFF_CLOCK_STREAM = 10


@dataclass
class ObservedPose:
    """What one pose produced: the reason it was dropped (None if accepted), the wrist in the
    base frame (accepted poses), and the events it settles as (kind, stamp ns)."""

    rejected: Optional[str] = None
    point: Optional[Tuple[float, float, float]] = None
    events: List[Tuple[str, int]] = field(default_factory=list)
    restarted: Optional[str] = None   # why this pose starts a new stream
    warning: Optional[str] = None     # once per episode of a stream on another clock
    held: bool = False                # held back: it may start a new stream (released later)
    # A new stream: the old stream's events it settles (published before anything of the new
    # one), then the poses held back for it (stamp ns, point), published before ``point``.
    ended: List[Tuple[str, int]] = field(default_factory=list)
    released: List[Tuple[int, Tuple[float, float, float]]] = field(default_factory=list)


@dataclass
class ObserverCounts:
    """``missing``: poses that never reached the observer (a queue overflowing, a network
    dropping them), estimated from gaps in the stamps of a stream at a regular rate."""

    accepted: int = 0
    missing: int = 0
    dropped: dict = field(default_factory=lambda: dict.fromkeys(POSE_REJECT_REASONS, 0))
    published: dict = field(default_factory=lambda: dict.fromkeys(
        ('observations', 'onset', 'end', 'gap'), 0))
    stream_restarts: int = 0


class WristObserver:

    def __init__(self, segmenter: MotionSegmenter, transform: FrameTransform = None, *,
                 expected_frame: str = '', quaternion_tolerance: float = 0.01,
                 restart_after_backwards: int = 50, max_clock_offset: float = 1.0,
                 limits: HumanLimits = HumanLimits(), new_stream_jump_back: float = 0.1,
                 new_stream_samples: int = 3):
        if not quaternion_tolerance >= 0:
            raise ValueError(f'quaternion_tolerance must be >= 0, got {quaternion_tolerance}')
        if not max_clock_offset >= 0:
            raise ValueError(f'max_clock_offset must be >= 0 s, got {max_clock_offset}')
        if not (new_stream_jump_back > 0 and math.isfinite(new_stream_jump_back)):
            raise ValueError(f'new_stream_jump_back must be > 0 s, got {new_stream_jump_back}')
        if int(new_stream_samples) != new_stream_samples or new_stream_samples < 0:
            raise ValueError(f'new_stream_samples must be a whole number >= 0, got '
                             f'{new_stream_samples}')
        self.max_clock_offset_ns = round(max_clock_offset * 1e9)
        self.jump_back_ns = round(new_stream_jump_back * 1e9)
        self.new_stream_samples = int(new_stream_samples)
        self.plausibility = MotionPlausibility(limits)
        self._jumped = MotionPlausibility(limits)    # judges the poses of a jump among themselves
        self._run = []                # (stamp ns, point, now ns) held back after a jump at rest
        self.clock_offset = None      # s, stamp minus clock of the latest pose off the clock
        self._off_clock = 0
        self.period = None            # s, the stream's sample period (estimated)
        self.segmenter = segmenter
        self.transform = transform if transform is not None else FrameTransform()
        self.expected_frame = expected_frame
        self.quaternion_tolerance = float(quaternion_tolerance)
        self.restart_after = int(restart_after_backwards)
        self.counts = ObserverCounts()
        self.moving = False           # between an 'onset' and its 'end'
        self._last_stamp_ns = None    # last accepted stamp
        self._t_ref_ns = None         # stream times are seconds since this stamp
        self._last_arrival_ns = None  # the caller's clock when the last pose was accepted
        self._backwards = 0

    def drop(self, reason: str) -> ObservedPose:
        self.counts.dropped[reason] += 1
        return ObservedPose(rejected=reason)

    def on_pose(self, stamp_ns: int, frame_id: str, position, orientation_xyzw,
                now_ns: int) -> ObservedPose:
        """One pose (position and unit quaternion (x, y, z, w) in the mocap frame)."""
        last_ns = self._run[-1][0] if self._run else self._last_stamp_ns
        reason = check_pose(stamp_ns, frame_id, position, orientation_xyzw, last_ns,
                            self.expected_frame, self.quaternion_tolerance)
        if reason in (None, 'duplicate_stamp', 'stamp_backwards') and self._off(stamp_ns, now_ns):
            out = self.drop('off_clock')
            self._off_clock += 1
            if self._off_clock == OFF_CLOCK_STREAM:
                out.warning = (f'the last {OFF_CLOCK_STREAM} wrist poses are stamped '
                               f'{self.clock_offset:+.3g} s from this node\'s clock: is the '
                               'motion capture on another clock (use_sim_time, time sync)? '
                               'They are dropped.')
            return out
        ended, why = [], None
        if reason == 'stamp_backwards':
            why = self._new_stream_in_time(stamp_ns, now_ns)
            if why is not None:
                ended = self._restart()
                reason = None
        if reason is not None:
            return self.drop(reason)
        point = self.transform.apply(*position)
        t = (stamp_ns - (stamp_ns if self._t_ref_ns is None else self._t_ref_ns)) * 1e-9
        if self._run:
            out = self._continue_jump(stamp_ns, t, point, now_ns)
            if out is not None:
                return out
        reason = self.plausibility.check(t, point)
        if reason == 'implausible_speed' and self.new_stream_samples > 0 and not self.moving:
            return self._start_jump(stamp_ns, t, point, now_ns)
        if reason is not None:
            return self.drop(reason)
        events = self._accept(stamp_ns, t, point, now_ns)
        return ObservedPose(point=point, events=events, restarted=why, ended=ended)

    def _accept(self, stamp_ns: int, t: float, point, now_ns: int) -> List[Tuple[str, int]]:
        """Take a pose that passed every check (``t``: s since the stream's first pose); the
        events it settles."""
        self.plausibility.accept(t, point)
        self._count_missing(stamp_ns)
        self._backwards = self._off_clock = 0
        if self._t_ref_ns is None:
            self._t_ref_ns = stamp_ns
        self._last_stamp_ns = stamp_ns
        self._last_point = point
        # Zero: simulated time whose /clock has not started yet; no basis to judge silences on.
        self._last_arrival_ns = now_ns if now_ns > 0 else None
        self.counts.accepted += 1
        self.counts.published['observations'] += 1
        return self._settle(self.segmenter.update(t, point))

    # -- new streams ------------------------------------------------------------------------
    def _new_stream_in_time(self, stamp_ns: int, now_ns: int) -> Optional[str]:
        """Why a pose older than the last accepted one starts a new stream (None: it does not,
        and is dropped)."""
        back = self._last_stamp_ns - stamp_ns
        if back > self.jump_back_ns:
            clock_judged = (self.max_clock_offset_ns > 0 and now_ns > 0
                            and self._last_arrival_ns is not None)
            # With a clock, the pose must be as near it as the old stream's last pose was when
            # it came: the clock jumped back with the stamps.
            if not clock_judged or abs((stamp_ns - now_ns) - (
                    self._last_stamp_ns - self._last_arrival_ns)) <= self.jump_back_ns:
                return f'the stamps jumped back {back * 1e-9:.3g} s'
        if self._restarted():
            return (f'{self.restart_after} consecutive poses older than the last accepted '
                    'one')
        return None

    def _start_jump(self, stamp_ns, t, point, now_ns) -> ObservedPose:
        """At rest, a pose no hand reaches from the last accepted one: held back as the first of
        a possible new stream."""
        self._drop_run()
        self._jumped.reset()
        self._jumped.accept(t, point)
        self._run = [(stamp_ns, point, now_ns)]
        return self._held_or_new_stream()

    def _continue_jump(self, stamp_ns, t, point, now_ns) -> Optional[ObservedPose]:
        """A pose after held-back ones: one more of them if it follows them as a hand moves
        (a new stream once there are enough); else they were a glitch, dropped, and None: the
        pose is judged against the stream as any other."""
        if self._jumped.check(t, point) is None:
            self._jumped.accept(t, point)
            self._run.append((stamp_ns, point, now_ns))
            return self._held_or_new_stream()
        self._drop_run()
        return None

    def _held_or_new_stream(self) -> ObservedPose:
        if len(self._run) < self.new_stream_samples:
            return ObservedPose(held=True)
        run, self._run = self._run, []
        first_ns, first, _ = run[0]
        jump = math.dist(first, self._last_point)
        why = (f'at rest, the wrist jumped {jump:.3g} m in '
               f'{(first_ns - self._last_stamp_ns) * 1e-9:.3g} s and stayed there')
        ended = self._restart()
        events = []
        for ns, p, now in run:
            events += self._accept(ns, (ns - (ns if self._t_ref_ns is None else
                                              self._t_ref_ns)) * 1e-9, p, now)
        return ObservedPose(point=run[-1][1], events=events, restarted=why, ended=ended,
                            released=[(ns, p) for ns, p, _ in run[:-1]])

    def _drop_run(self) -> None:
        for _ in self._run:
            self.counts.dropped['implausible_speed'] += 1
        self._run = []

    def _count_missing(self, stamp_ns: int) -> None:
        """Track the sample period (it adapts slowly; longer steps do not move it) and count the
        samples a longer step skipped; a silence beyond gap_timeout is a gap, not losses."""
        if self._last_stamp_ns is None:
            return
        dt = (stamp_ns - self._last_stamp_ns) * 1e-9
        if self.period is None or dt < 1.5 * self.period:
            self.period = dt if self.period is None else self.period + 0.05 * (dt - self.period)
        elif dt <= self.segmenter.gap_timeout:
            self.counts.missing += int(round(dt / self.period)) - 1

    def _off(self, stamp_ns: int, now_ns: int) -> bool:
        """Whether the stamp is too far from the clock (not judged before the clock runs)."""
        if self.max_clock_offset_ns <= 0 or now_ns <= 0:
            return False
        if abs(stamp_ns - now_ns) <= self.max_clock_offset_ns:
            return False
        self.clock_offset = (stamp_ns - now_ns) * 1e-9
        return True

    def on_timer(self, now_ns: int) -> List[Tuple[str, int]]:
        """Events a silence of the stream settles, judged at ``now_ns`` on the caller's clock."""
        if self._last_arrival_ns is None:
            return []
        silence = (now_ns - self._last_arrival_ns) * 1e-9
        if silence <= self.segmenter.gap_timeout:
            return []
        return self._settle(self.segmenter.gap(self.segmenter.last_time + silence))

    def _settle(self, events: List[Event]) -> List[Tuple[str, int]]:
        out = []
        for ev in events:
            out.append((ev.kind, self._t_ref_ns + round(ev.time * 1e9)))
            self.counts.published[ev.kind] += 1
            if ev.kind in ('onset', 'end'):
                self.moving = ev.kind == 'onset'
        return out

    def _restarted(self) -> bool:
        """Count a pose older than the last accepted one; True once the stream restarted."""
        if self.restart_after <= 0:
            return False
        self._backwards += 1
        return self._backwards >= self.restart_after

    def _restart(self) -> List[Tuple[str, int]]:
        """Forget the old stream; an interaction in progress ends at its last sample."""
        self._drop_run()
        events = []
        last_t = self.segmenter.last_time
        if self.moving and last_t is not None:
            events = self._settle([Event('end', last_t)])
        self.segmenter.reset()
        self.plausibility.reset()
        self.period = None
        self.moving = False
        self._t_ref_ns = self._last_stamp_ns = self._last_arrival_ns = None
        self._backwards = 0
        self.counts.stream_restarts += 1
        return events
