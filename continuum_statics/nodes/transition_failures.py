"""Why a lifecycle transition of cable_driver failed, on ``/diagnostics`` (issue 44).

A configure whose backend refuses its options (``sim.dynamics`` on a robot file without real
tendons) or an activate the actuators refuse used to be in the log only, so ``doctor`` sent the
user to a ``configure`` that failed the same way. The reason now stays on the driver's status
(level ERROR, value ``transition_failure``) until a transition succeeds.
"""
from rclpy.lifecycle import TransitionCallbackReturn

from continuum_statics.control.health import ERROR


class _ErrorRecorder:
    """A logger that keeps the text of its last ``error`` line (the actuators' failures)."""

    def __init__(self, logger):
        self._logger = logger
        self.last_error = ''

    def error(self, text, *args, **kwargs):
        """Log ``text`` as an error and keep it."""
        self.last_error = str(text)
        return self._logger.error(text, *args, **kwargs)

    def __getattr__(self, name):  # info, warning, ...: the node's logger's own
        return getattr(self._logger, name)


class TransitionFailures:
    """Mixin of a lifecycle node: the last failed transition and its reason, while it holds."""

    _transition_failure = ''
    _error_recorder = None

    def _recording(self):
        """Return the node's logger, wrapped so that its last error can name a failure."""
        self._error_recorder = _ErrorRecorder(self.get_logger())
        return self._error_recorder

    def _transition_failed(self, transition, error=None):
        """Log and keep why ``transition`` failed; return FAILURE for the transition callback.

        ``error`` None: the reason is the last error the recorded logger saw (the actuators log
        why a backend refused to power on or off).
        """
        if error is not None:
            self._transition_failure = '%s failed: %s' % (transition, error)
            self.get_logger().error(self._transition_failure)
        else:
            seen = self._error_recorder.last_error if self._error_recorder else ''
            self._transition_failure = seen or '%s failed (see its log)' % transition
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
