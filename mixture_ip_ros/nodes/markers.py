"""RViz markers of what the estimator predicts: the person's wrist path under every component
(more opaque the more probable) and the robot hand's planned path, in one fixed frame."""

from geometry_msgs.msg import Point
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

NAMESPACE_WRIST = 'predicted_wrist'
NAMESPACE_HAND = 'planned_hand'
NAMESPACE_LABEL = 'component_label'
# Matplotlib's tab10, so RViz and the evaluation plots colour components alike.
PALETTE = ((0.12, 0.47, 0.71), (1.0, 0.5, 0.05), (0.17, 0.63, 0.17), (0.84, 0.15, 0.16),
           (0.58, 0.4, 0.74), (0.55, 0.34, 0.29), (0.89, 0.47, 0.76), (0.5, 0.5, 0.5),
           (0.74, 0.74, 0.13), (0.09, 0.75, 0.81))
MIN_ALPHA = 0.1     # an improbable component stays faintly visible
LINE_WIDTH = 0.01   # m


def _line(ns, marker_id, frame, stamp, points, rgba, width=LINE_WIDTH) -> Marker:
    m = Marker(ns=ns, id=int(marker_id), type=Marker.LINE_STRIP, action=Marker.ADD)
    m.header.frame_id = frame
    m.header.stamp = stamp
    m.pose.orientation.w = 1.0
    m.scale.x = width
    m.color = ColorRGBA(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])
    m.points = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in points]
    return m


def prediction_markers(frame: str, stamp, paths, hand=None, labels=None) -> MarkerArray:
    """``paths``: (component, probability, positions (n, 3)) per component; ``hand``: the robot
    hand's planned positions (n, 3) or None; ``labels``: a name per path (shown at its end)."""
    out = MarkerArray()
    for i, (k, probability, positions) in enumerate(paths):
        r, g, b = PALETTE[k % len(PALETTE)]
        alpha = max(MIN_ALPHA, float(probability))
        out.markers.append(_line(NAMESPACE_WRIST, k, frame, stamp, positions, (r, g, b, alpha)))
        if labels is not None and len(positions):
            text = Marker(ns=NAMESPACE_LABEL, id=int(k), type=Marker.TEXT_VIEW_FACING,
                          action=Marker.ADD, text=f'{labels[i]} {probability:.2f}')
            text.header.frame_id = frame
            text.header.stamp = stamp
            x, y, z = (float(v) for v in positions[-1])
            text.pose.position = Point(x=x, y=y, z=z + 0.05)
            text.pose.orientation.w = 1.0
            text.scale.z = 0.04
            text.color = ColorRGBA(r=r, g=g, b=b, a=alpha)
            out.markers.append(text)
    if hand is not None and len(hand):
        out.markers.append(_line(NAMESPACE_HAND, 0, frame, stamp, hand, (0.1, 0.1, 0.1, 1.0),
                                 width=2 * LINE_WIDTH))
    else:   # not committed (any more): no stale plan on the screen
        gone = Marker(ns=NAMESPACE_HAND, id=0, action=Marker.DELETE)
        gone.header.frame_id = frame
        gone.header.stamp = stamp
        out.markers.append(gone)
    return out
