"""Who commands the arm: one configured node, and whether its commands still have a source.
ROS-free: the sim node feeds :class:`CommandWatch` the publishers the ROS graph shows on its
command topic and its subscription's liveliness changes, and asks it what to do.

One commander. A command is taken only while every publisher matched on the topic is the
commander's (its node name, in any namespace, or its full name). rclpy 7.1 hands a
subscription callback no sender (its message info has no publisher gid), so a command cannot
be traced to the publisher that sent it: while another publisher that can deliver is on the
topic, or the subscription has matched more publishers than the graph gives the commander
(one discovered but not yet named), every command is refused. Each other publisher is warned
about once; one whose QoS cannot match the subscription never delivers and is only reported.
A command that only stops the arm (an empty trajectory) is taken from anyone.

Liveliness. With a lease, DDS tells the subscriber when a publisher on the topic stops
asserting its liveliness (its process is gone, or stalled longer than the lease) or leaves:
the arm then stops following its plan. Any publisher's loss stops it: the subscriber is not
told whose it was. ``now`` (s, the caller's clock) dates what happened, for reports.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional


@dataclass(frozen=True)
class Publisher:
    """A publisher on the command topic, as the ROS graph shows it."""

    node: str            # its node's full name ('/ns/name'); '' while the graph has no name
    gid: bytes
    compatible: bool     # its QoS matches the subscription's (else none of its messages arrive)


def is_commander(node: str, commander: str) -> bool:
    """Whether ``node`` (a full name) is ``commander``: a full name ('/arm/estimator_node') or a
    node name in any namespace ('estimator_node'); '' is any node."""
    if not commander:
        return True
    if commander.startswith('/'):
        return node == commander
    return bool(node) and node.rsplit('/', 1)[-1] == commander


class CommandWatch:
    """The decisions of the sim about its command topic; see the module docstring.

    ``commander`` '' takes commands from any publisher. Counters: ``refused`` commands not
    taken, ``others`` other publishers seen, ``incompatible`` publishers whose QoS cannot
    match, ``lapses`` publishers whose liveliness was lost, ``holds`` plans stopped for it."""

    def __init__(self, commander: str):
        self.commander = commander
        self.refused = 0
        self.others = 0
        self.incompatible = 0
        self.lapses = 0
        self.holds = 0
        self.last_lapse: Optional[float] = None
        self.alive: Optional[int] = None      # publishers alive, as the latest change said
        self._blocked: Optional[str] = None   # why commands are refused now
        self._told = False                    # the refusal of this blocked spell was logged
        self._seen = set()                    # gids of other publishers already reported

    @property
    def blocked(self) -> Optional[str]:
        """Why commands are refused now, or None."""
        return self._blocked

    def graph(self, publishers, matched: int) -> list:
        """The publishers the graph shows on the topic and how many the subscription has
        matched. Returns a warning for each other publisher not reported before."""
        if not self.commander:
            self._blocked = None
            return []
        ours = [p for p in publishers if is_commander(p.node, self.commander)]
        others = [p for p in publishers if not is_commander(p.node, self.commander)]
        delivering = [p for p in others if p.compatible]
        blocked = None
        if delivering:
            names = sorted({p.node or 'a publisher not named yet' for p in delivering})
            blocked = f'another publisher on the command topic: {", ".join(names)}'
        elif matched > sum(p.compatible for p in ours):
            blocked = 'a publisher on the command topic that the ROS graph does not name yet'
        if blocked != self._blocked:
            self._told = False
        self._blocked = blocked
        warnings = []
        for p in others:
            if not p.node or p.gid in self._seen:
                continue
            self._seen.add(p.gid)
            self.others += 1
            if p.compatible:
                warnings.append(f'{p.node} publishes on the command topic too: no command is '
                                f'taken while it does (only {self.commander} commands the arm, '
                                'and a message does not say who sent it)')
            else:
                warnings.append(f'{p.node} publishes on the command topic with a QoS the sim '
                                'does not accept: none of its messages arrive')
        return warnings

    def accept(self, stop: bool = False) -> tuple:
        """Whether a command arriving now is taken: (True, None), or (False, a line to log:
        None once this spell of refusals was logged). ``stop``: it only stops the arm."""
        if stop or self._blocked is None:
            return True, None
        self.refused += 1
        if self._told:
            return False, None
        self._told = True
        return False, f'commands refused: {self._blocked}'

    def incompatible_publisher(self) -> str:
        """A publisher whose QoS cannot match was discovered: a line to log."""
        self.incompatible += 1
        return ('a publisher on the command topic offers a QoS the sim does not accept (the '
                'reliability, or a liveliness lease longer than command_lease): none of its '
                'messages arrive')

    def liveliness(self, alive: int, change: int, now: float, following: bool) -> bool:
        """A change of the publishers' liveliness (``alive`` publishers now, ``change`` since
        the last); ``following``: the arm is on a plan. True: stop following it and hold."""
        self.alive = int(alive)
        if change >= 0:
            return False
        self.lapses += 1
        self.last_lapse = float(now)
        if following:
            self.holds += 1
        return following
