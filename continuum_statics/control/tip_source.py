"""Which tip a goal is judged on, and when an external tracker stops being trusted.

A tracker (``tip_pose_measured``: motion capture, an EM sensor) closes the loop on the real tip,
but a frozen, biased or jumping tracker once walked the robot 120-214 mm across its workspace one
correction at a time. The tracker is trusted only while it agrees with the model's tip
(``tip_pose``, the estimate of the measured cable lengths) within ``bound``: a calibrated model is
within millimetres of the real tip (11 mm RMS held out on the v6 robot, README), so a tracker
further away than a tenth of the rod length is more likely wrong than the model. Outside the
bound the tracker is set aside for the rest of the goal, with a warning that names it, and the
goal continues on the model. A reading is compared with the model's tip of its own time, the
latest time both have (:func:`matched`): while the tip moves, the newest reading, up to
``max_state_age`` old, lay 30-49 mm from the newest model tip though within 0.2-4 mm of the one
of its time, and an honest tracker was set aside 74 times in ten minutes of normal use (issue
43); the other way round, statics lagging under load, twice in ten minutes. No ROS.
"""
import numpy as np

#: Default ``tracker_max_disagreement`` as a fraction of the rod length.
DISAGREEMENT_FRACTION = 0.1
#: Longest time (s) between a tracker sample and the model tip it is compared with: a few
#: samples of either stream (a tracker at 100 Hz, statics at 20 Hz on a loaded computer).
MATCH_WINDOW = 0.1


def disagreement_bound(robot_length, parameter):
    """Return the bound (m): ``tracker_max_disagreement``, or 0.1 L when it is 0."""
    return parameter if parameter > 0.0 else DISAGREEMENT_FRACTION * robot_length


class TipSource:
    """Chooses tracker or model tip per control tick; ``set_aside`` says why not the tracker."""

    def __init__(self, bound):
        self.bound = bound  # m
        self.set_aside = ''  # the warning, once the tracker is set aside for this goal

    def reset(self):
        """Give the tracker its trust back (a new goal)."""
        self.set_aside = ''

    def judged(self, now, measured, measured_tips, model, model_tips, max_age, use_measured):
        """(newest sample, recent samples, source name, new warning or '') to judge a goal on.

        The tracker while it is fresh, wanted and within ``bound`` of the model's tip; else the
        model's ``tip_pose``, on which the loop closes through the estimate of the lengths.
        """
        tracker = use_measured and measured is not None and measured.age(now) <= max_age
        if not tracker or self.set_aside:
            return model, model_tips, 'tip_pose', ''
        pair = None if model is None else matched(measured, measured_tips, model, model_tips)
        if pair is not None:
            gap = float(np.linalg.norm(pair[0].position - pair[1].position))
            if gap > self.bound:
                self.set_aside = (
                    'tracker set aside: tip_pose_measured is %.1f mm from the model tip '
                    '(tip_pose), more than tracker_max_disagreement %.1f mm (a frozen, biased '
                    'or jumping tracker, or a wrong registration?); the goal continues on the '
                    'model' % (gap * 1e3, self.bound * 1e3))
                return model, model_tips, 'tip_pose', self.set_aside
        return measured, measured_tips, 'tip_pose_measured', ''


def matched(measured, measured_tips, model, model_tips, window=MATCH_WINDOW):
    """Return (tracker sample, model tip) of one time, the latest both streams have, or None.

    The older of the two streams' newest samples is matched with the other stream's sample of
    its time: the newest reading with the model tip of its time, or, while statics lags behind
    the tracker (its newest ``tip_pose`` 0.3 s old while the tip moves 0.1 m/s: 30 mm), the
    model's newest tip with the tracker's reading of its time. None when no pair lies within
    ``window`` s.
    """
    stamped = bool(measured.stamp_ns and model.stamp_ns)
    if _time(model, stamped) < _time(measured, stamped):
        pair = (at_time_of(model, measured_tips) or measured, model)
    else:
        pair = (measured, at_time_of(measured, model_tips) or model)
    if abs(_time(pair[0], stamped) - _time(pair[1], stamped)) > window:
        return None
    return pair


def _time(sample, stamped):
    return sample.stamp_ns * 1e-9 if stamped else sample.received


def at_time_of(sample, samples):
    """Return the sample of ``samples`` (oldest first) nearest ``sample`` in time, or None.

    By stamp when both carry one (the measurement's time), else by arrival.
    """
    def time_of(other):
        return other.stamp_ns * 1e-9 if stamped else other.received

    best, gap = None, np.inf
    stamped = bool(sample.stamp_ns)
    when = time_of(sample)
    for other in reversed(samples):  # newest first: the nearest is usually among the last
        if stamped and not other.stamp_ns:
            continue
        distance = abs(time_of(other) - when)
        if distance > gap:
            break  # samples are in time order: further back only gets further
        best, gap = other, distance
    return best
