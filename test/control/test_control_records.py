"""The tip load a node takes: zero after tip_wrench_timeout, an estimate's kept (issue 43)."""
import numpy as np

from continuum_statics.control.records import TipLoadInput

LOAD = np.array([0.12, -0.08, 0.0, 0.0, 0.0, 0.0])


class Clock:
    def __init__(self):
        self.now = 10.0

    def __call__(self):
        return self.now


def make(hold):
    clock, said = Clock(), []
    source = TipLoadInput('tip_wrench_estimate' if hold else 'tip_wrench', hold,
                          lambda text: said.append(('warn', text)),
                          lambda text: said.append(('info', text)), clock)
    return source, clock, said


def test_without_a_load_it_is_zero_and_nothing_is_said():
    source, _, said = make(hold=True)
    np.testing.assert_array_equal(source.current(3.0), np.zeros(6))
    assert source.age() == np.inf and source.status() == '' and not said


def test_a_tip_wrench_expires_to_zero_once_and_comes_back():
    source, clock, said = make(hold=False)
    source.take(LOAD)
    clock.now += 2.9
    np.testing.assert_array_equal(source.current(3.0), LOAD)
    clock.now += 0.2
    for _ in range(3):
        np.testing.assert_array_equal(source.current(3.0), np.zeros(6))
    assert said == [('warn', 'tip_wrench is older than 3 s: using zero tip load')]
    assert source.expired and source.status() == ''  # zero load is no load kept
    source.take(2 * LOAD)
    np.testing.assert_array_equal(source.current(3.0), 2 * LOAD)
    assert not source.expired and said[-1] == ('info', 'tip_wrench received again')


def test_an_estimate_is_kept_past_the_timeout_with_a_warning_and_a_status():
    """Before: zero load after 3 s of a late estimator moved the model tip 10 mm."""
    source, clock, said = make(hold=True)
    source.take(LOAD)
    clock.now += 4.5
    np.testing.assert_array_equal(source.current(3.0), LOAD)
    assert said == [('warn', 'tip_wrench_estimate is older than 3 s: its last load kept '
                             '(the estimator is late or stopped)')]
    assert source.status() == 'tip_wrench_estimate 4.5 s old: its last load kept'
    source.drop()  # the model cannot take it: zero, whatever the source
    np.testing.assert_array_equal(source.current(3.0), np.zeros(6))
    assert source.status() == ''


def test_a_timeout_of_zero_never_expires():
    source, clock, said = make(hold=False)
    source.take(LOAD)
    clock.now += 1e6
    np.testing.assert_array_equal(source.current(0.0), LOAD)
    assert not said
