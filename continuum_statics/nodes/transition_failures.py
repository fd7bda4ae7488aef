"""Why a lifecycle transition of cable_driver failed, on ``/diagnostics`` (issue 44).

A configure whose backend refuses its options (``sim.dynamics`` on a robot file without real
tendons) or an activate the actuators refuse used to be in the log only, so ``doctor`` sent the
user to a ``configure`` that failed the same way. The reason now stays on the driver's status
(level ERROR, value ``transition_failure``) until a transition succeeds.
"""
from rclpy.lifecycle import TransitionCallbackReturn

from continuum_statics.control.health import ERROR


class TransitionFailures:
    """Mixin of a lifecycle node: the last failed transition and its reason, while it holds."""

    _transition_failure = ''

    def _transition_failed(self, reason):
        """Keep (and log) ``reason``, e.g. 'activate failed: ...'; return FAILURE."""
        self._transition_failure = reason
        self.get_logger().error(reason)
        return TransitionCallbackReturn.FAILURE

    def _transition_done(self):
        """Forget a failed transition (a later one succeeded); return SUCCESS."""
        self._transition_failure = ''
        return TransitionCallbackReturn.SUCCESS

    def _with_transition_failure(self, health):
        """Return (level, message, values) of ``health``, ERROR naming a failed transition."""
        level, message, values = health
        if not self._transition_failure:
            return level, message, values
        values['transition_failure'] = self._transition_failure
        return ERROR, '%s (lifecycle %s)' % (self._transition_failure,
                                             values.get('lifecycle', '?')), values
