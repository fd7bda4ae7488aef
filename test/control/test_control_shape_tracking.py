"""Shape tracking without DDS: what statics decides for each measurement."""
from conftest import REPO
import numpy as np
import pytest

from continuum_statics import load_robot
from continuum_statics.control.shape_tracking import ShapeTracker, Thresholds

ROBOT = load_robot(REPO / 'config' / 'tendon_robot.yaml')
THRESHOLDS = Thresholds(warn=1e-4, drop=2e-3, margin=1e-3)
ZERO = np.zeros(6)


def tracker(max_iterations=3):
    return ShapeTracker(ROBOT, ROBOT.cable_names, max_iterations)


def test_noise_raises_the_thresholds_to_3_10_and_5_sigma():
    t = Thresholds.with_noise(1e-4, 2e-3, 1e-3, 1e-3)
    assert (t.warn, t.drop, t.margin) == (3e-3, 1e-2, 5e-3)
    assert Thresholds.with_noise(1e-4, 2e-3, 1e-3, 0.0) == THRESHOLDS


def test_lengths_of_a_shape_are_published_and_warm_start_the_next():
    shape = ROBOT.solve_ivp([2.0, -1.0, 0.0])
    track = tracker()
    result = track.update(ROBOT.cable_lengths(shape), None, ZERO, THRESHOLDS, 100.0)
    assert result.rejection == '' and not result.best_fit
    np.testing.assert_allclose(result.estimate.shape.tip_position, shape.tip_position,
                               atol=1e-6)
    track.accept(result)
    assert track.warm is result.estimate


def test_lengths_no_shape_fits_are_dropped_and_a_small_misfit_is_a_best_fit():
    lengths = ROBOT.straight_cable_lengths.copy()
    lengths -= 0.004  # every cable pulled in: no rod shape has these lengths, taut or slack
    result = tracker().update(lengths, None, ZERO, THRESHOLDS, 100.0)
    assert 'fit no shape' in result.rejection and result.residual > 2e-3
    lengths = ROBOT.straight_cable_lengths - 2e-4
    result = tracker().update(lengths, None, ZERO, THRESHOLDS, 100.0)
    assert result.rejection == '' and result.best_fit and 'best fit' in result.message


def test_lengths_no_shape_fits_under_the_load_give_the_shape_under_zero_load():
    # issue 43 item 4, before: a tip load estimate the lengths fit no shape under (RMS 17.6 mm)
    # dropped every cable_states ("cable lengths fit no shape"): statics silent for 13 s
    shape = ROBOT.solve_ivp([2.0, -1.0, 0.0])
    load = np.array([5.0, 5.0, 0.0, 0.0, 0.0, 0.0])
    result = tracker().update(ROBOT.cable_lengths(shape), None, load, THRESHOLDS, 100.0)
    assert result.rejection == '', result.rejection
    assert 'fit no shape under tip load [5. 5. 0. 0. 0. 0.]' in result.load_problem
    np.testing.assert_allclose(result.estimate.shape.tip_position, shape.tip_position,
                               atol=1e-6)
    # lengths no shape fits under any load are still dropped
    pulled = ROBOT.straight_cable_lengths - 0.004
    result = tracker().update(pulled, None, load, THRESHOLDS, 100.0)
    assert 'fit no shape' in result.rejection and not result.load_problem


def test_every_cable_paid_out_is_the_passive_rod_with_slack_cables():
    # real robots under displacement control: the cables go slack and the rod hangs passive
    lengths = ROBOT.straight_cable_lengths + 0.004
    result = tracker().update(lengths, None, ZERO, THRESHOLDS, 100.0)
    assert result.rejection == '' and not result.best_fit
    assert result.estimate.slack.all() and np.all(result.estimate.tensions == 0.0)
    passive = ROBOT.solve_bvp()
    np.testing.assert_allclose(result.estimate.shape.tip_position, passive.tip_position,
                               atol=1e-9)


def test_lengths_outside_the_limits_and_implausible_tensions_are_rejected_unsolved():
    lengths = ROBOT.straight_cable_lengths.copy()
    lengths[2] = ROBOT.cable_length_limits[2, 1] + 2e-3
    result = tracker().update(lengths, None, ZERO, THRESHOLDS, 100.0)
    assert result.outside_limits and result.estimate is None and 'cable_2' in result.rejection
    tensions = np.array([1e6, 0.0, 0.0, 0.0])
    result = tracker().update(ROBOT.straight_cable_lengths, tensions, ZERO, THRESHOLDS, 100.0)
    assert result.estimate is None and 'cable_0 1e+06 N' in result.rejection


def test_tensions_that_disagree_with_the_lengths_are_set_aside():
    bent = ROBOT.solve_ivp([2.0, 0.0, 0.0])
    result = tracker().update(ROBOT.cable_lengths(bent), np.zeros(4), ZERO, THRESHOLDS, 100.0)
    assert 'tensions disagree' in result.distrust and not result.tensions_used
    np.testing.assert_allclose(result.estimate.shape.tip_position, bent.tip_position, atol=1e-5)


def test_a_tip_load_the_model_cannot_take_is_blamed_on_tip_wrench():
    class Model:
        """Stands in for a robot whose model is not finite under any tip load."""

        def estimate_shape(self, lengths, tip_force=(0.0, 0.0, 0.0), tip_moment=(0.0, 0.0, 0.0),
                           tensions=None, warm_start=None, tracking=None, sensors=None,
                           stamp=None):
            if np.any(tip_force) or np.any(tip_moment):
                raise ValueError('the model is not finite at the start')
            return 'unloaded estimate'

    notes = {'load_problem': ''}
    estimate = ShapeTracker._estimate(Model(), np.full(4, 0.3), np.ones(6), None, None, notes)
    assert estimate == 'unloaded estimate'
    assert 'no finite shape under tip load' in notes['load_problem']


def test_without_a_tip_load_a_model_failure_is_left_to_the_caller():
    class Model:
        def estimate_shape(self, *args, **kwargs):
            raise ValueError('cable lengths no shape can have')

    with pytest.raises(ValueError, match='no shape'):
        ShapeTracker._estimate(Model(), np.full(4, 0.3), np.zeros(6), None, None, {})


def test_sensor_inbox_fuses_each_reading_once_and_counts_verdicts():
    from continuum_statics.control.sensor_readings import SensorInbox
    from continuum_statics.core.description.sensors import SensorVerdict

    inbox = SensorInbox(['tip_tracker', 'coil'], timeout=0.5)
    assert inbox.take(0.0) is None
    inbox.put('tip_tracker', (0.0, 0.0, 0.3), None, 10.0, now=1.0)
    inbox.put('coil', (0.0, 0.0, 0.1), None, 10.0, now=0.2)
    taken = inbox.take(1.1)
    assert list(taken) == ['tip_tracker'] and inbox.records['coil'].stale == 1
    assert inbox.take(1.2) is None  # read once
    inbox.put('tip_tracker', (0.0, float('nan'), 0.3), None, 11.0, now=1.3)
    assert inbox.records['tip_tracker'].rejected == 1 and inbox.take(1.3) is None
    inbox.judged({'tip_tracker': SensorVerdict(False, 80.0, 'innovation chi2 80.0 above')})
    assert inbox.records['tip_tracker'].set_aside == 1
    assert 'tip_tracker set aside' in inbox.problems(1.3)
    assert 'silent' in inbox.problems(5.0)
    assert 'set aside 1' in inbox.values(1.3)['sensor_tip_tracker']


@pytest.mark.parametrize('stamp, word', [(1.0, 'before'), (98.0, 'before'), (110.0, 'ahead of')],
                         ids=['1970', '2 s old', '10 s ahead'])
def test_a_reading_is_judged_by_its_stamp_not_by_its_arrival(stamp, word):
    # issue 43 item 7, before: readings stamped 1970, 2 s old or 10 s ahead were fused as fresh
    from continuum_statics.control.sensor_readings import SensorInbox

    inbox = SensorInbox(['tip_tracker'], timeout=0.5, max_offset=1.0)
    inbox.put('tip_tracker', (0.0, 0.0, 0.3), None, stamp, now=1.0, clock_now=100.0)
    record = inbox.records['tip_tracker']
    assert inbox.take(1.0) is None and record.rejected == 1
    assert word in record.last_reason and 'max_stamp_offset 1 s' in record.last_reason
    inbox.put('tip_tracker', (0.0, 0.0, 0.3), None, 99.5, now=1.1, clock_now=100.0)
    assert list(inbox.take(1.1)) == ['tip_tracker']  # a fresh stamp is fused
    inbox.put('tip_tracker', (0.0, 0.0, 0.3), None, None, now=1.2, clock_now=100.0)
    assert list(inbox.take(1.2)) == ['tip_tracker']  # unstamped: judged by arrival


def test_a_reading_stamped_after_the_measurement_waits_for_a_later_one():
    # before: a late measurement took a reading stamped after it; fused at the measurement's
    # stamp, the correction then decayed over an interval the reading had not yet been taken in
    # (a statics under a CPU hog: a 2 mm reading, 1 s later, with a 0.5 s correlation time,
    # moved the fused tip 0.27 mm, not 2 mm)
    from continuum_statics.control.sensor_readings import SensorInbox

    inbox = SensorInbox(['tip_tracker'], timeout=0.5)
    inbox.put('tip_tracker', (0.0, 0.0, 0.3), None, 101.0, now=1.0)
    assert inbox.take(1.05, stamp=100.0) is None and inbox.records['tip_tracker'].stale == 0
    assert inbox.take(1.06, stamp=101.0)['tip_tracker'].stamp == 101.0
    inbox.put('tip_tracker', (0.0, 0.0, 0.3), None, 102.0, now=1.2)
    assert inbox.take(1.21, stamp=101.5) is None
    inbox.put('tip_tracker', (0.0, 0.0, 0.3), None, 102.5, now=1.3)  # newer: replaces it
    assert inbox.take(1.31, stamp=103.0)['tip_tracker'].stamp == 102.5
    # a clock ahead of every measurement: used at half the timeout after its arrival anyway
    inbox.put('tip_tracker', (0.0, 0.0, 0.3), None, 110.0, now=2.0)
    assert inbox.take(2.2, stamp=105.0) is None
    assert list(inbox.take(2.26, stamp=105.1)) == ['tip_tracker']
    inbox.put('tip_tracker', (0.0, 0.0, 0.3), None, 120.0, now=3.0)
    assert list(inbox.take(3.0)) == ['tip_tracker']  # no measurement stamp: taken as before


def test_only_the_judged_reading_is_passed_on():
    # issue 43 item 7, before: sensors/<name>/accepted republished the newest message (in 8 s
    # 345 "accepted", 136 of them NaN and 26 the gate had set aside)
    from continuum_statics.control.sensor_readings import SensorInbox
    from continuum_statics.core.description.sensors import SensorVerdict

    inbox = SensorInbox(['tip_tracker', 'coil'], timeout=0.5)
    inbox.put('tip_tracker', (0.0, 0.0, 0.3), None, None, now=1.0, source='judged')
    inbox.put('coil', (0.0, 0.0, 0.1), None, None, now=1.0, source='coil reading')
    assert set(inbox.take(1.0)) == {'tip_tracker', 'coil'}
    inbox.put('tip_tracker', (0.0, float('nan'), 0.3), None, None, now=1.01, source='nan')
    inbox.put('coil', (0.0, 0.0, 0.2), None, None, now=1.01, source='newer, not judged')
    verdicts = {'tip_tracker': SensorVerdict(True, 1.0, ''),
                'coil': SensorVerdict(False, 80.0, 'innovation chi2 80.0 above')}
    assert inbox.used_sources(verdicts) == [('tip_tracker', 'judged')]
