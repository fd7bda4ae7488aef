"""The node-test harness itself: what raises in a node fails the test, never in silence."""
import pytest

rclpy = pytest.importorskip('rclpy')
from nodes_helpers import Harness, wait_until  # noqa: E402
from rclpy.node import Node  # noqa: E402

from continuum_statics.nodes.node_runner import RunnerHooks  # noqa: E402

pytestmark = pytest.mark.ros  # starts DDS


class Failing(RunnerHooks, Node):
    """A node whose timer raises once, and that counts a failure of its own once."""

    def __init__(self, **kwargs):
        super().__init__('failing', **kwargs)
        self.counted = []
        self._timer = self.create_timer(0.01, self._tick)

    def on_node_failure(self, text):
        self.counted.append(text)

    def _tick(self):
        self._timer.cancel()
        self.on_node_failure('intake failed: ValueError()')  # as the intake thread reports
        raise RuntimeError('one bad measurement')


def test_a_raising_callback_and_a_counted_failure_fail_the_test_at_close():
    harness = Harness()
    node = harness.add(Failing)
    wait_until(lambda: len(harness.failures) == 2, 10.0, 'both failures')
    assert node.counted == ['intake failed: ValueError()']  # the node still counts its own
    with pytest.raises(AssertionError, match='one bad measurement'):
        harness.close()
