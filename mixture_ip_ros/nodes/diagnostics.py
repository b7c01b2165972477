"""The one way the nodes report on /diagnostics: one DiagnosticStatus per message."""

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

OK, WARN = DiagnosticStatus.OK, DiagnosticStatus.WARN


def diagnostic_array(stamp, name: str, level: bytes, message: str, values: dict):
    """A DiagnosticArray with one status; ``values`` {key: value} as strings (None as '')."""
    status = DiagnosticStatus(name=name, hardware_id='mixture_ip_ros', level=level,
                              message=message)
    status.values = [KeyValue(key=k, value='' if v is None else str(v))
                     for k, v in values.items()]
    msg = DiagnosticArray(status=[status])
    msg.header.stamp = stamp
    return msg


class PublishesDiagnostics:
    """The diagnostics timer's callback, for a node with a ``diagnostics_pub`` publisher, a
    ``diagnostics_msg()`` and a ``log_throttle_sec`` parameter."""

    def publish_diagnostics(self) -> None:
        # A report that cannot be built or sent is logged, never raised: the node's work goes on.
        try:
            self.diagnostics_pub.publish(self.diagnostics_msg())
        except Exception as exc:
            self.get_logger().error(f'diagnostics failed: {exc!r}',
                                    throttle_duration_sec=self.params.log_throttle_sec)
