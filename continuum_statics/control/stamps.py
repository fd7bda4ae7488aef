"""Which stamp an output carries and how fresh an input is: its own, when trusted (no ROS).

A measurement's stamp is the time it was taken, and outputs (/tf, ``backbone``, ``tip_pose``,
``tip_wrench_estimate``) carry it. A stamp is not trusted when it is more than ``max_offset``
from the node's clock (a micro-controller that never synchronised stamps 1970; a clock a day
ahead) or goes backwards against the previous output of that stream (two sources mixed: /tf
must not go back in time). Such a stamp is replaced by the arrival time, counted, and the
reason is returned for a throttled warning. An unstamped message (zero) is stamped on arrival
without a warning (documented behaviour of the drivers' simple bridges).
"""

_NS = 1_000_000_000


class StampRule:
    """Judge the stamps of one node's inputs, stream by stream (e.g. 'cable_states').

    :param max_offset: s a stamp may be away from the node's clock
    :ivar replaced: {stream: how many stamps were replaced by the arrival time}
    """

    def __init__(self, max_offset):
        self.max_offset = float(max_offset)
        self.replaced = {}
        self._last = {}  # stream -> the last stamp given out, ns

    def judge(self, stream, stamp_ns, now_ns):
        """Return (the stamp to use, ns; the reason it was replaced, or '')."""
        reason = ''
        last = self._last.get(stream)
        if stamp_ns == 0:
            stamp_ns = now_ns
        elif abs(stamp_ns - now_ns) > self.max_offset * _NS:
            reason = ("%s stamped %.6g s from this node's clock (max_stamp_offset %g s): "
                      'stamped on arrival instead (is its clock synchronised?)'
                      % (stream, (stamp_ns - now_ns) / _NS, self.max_offset))
        elif last is not None and stamp_ns < last:
            reason = ('%s stamp %.3f s before the previous one (two sources mixed?): stamped '
                      'on arrival instead' % (stream, (last - stamp_ns) / _NS))
        if reason:
            self.replaced[stream] = self.replaced.get(stream, 0) + 1
            stamp_ns = max(now_ns, last or 0)  # never backwards
        self._last[stream] = stamp_ns
        return stamp_ns, reason

    def judge_age(self, stream, stamp_ns, now_ns):
        """Return (the stamp to use, ns; its age, s; the reason it was replaced, or '')."""
        stamp_ns, reason = self.judge(stream, stamp_ns, now_ns)
        return stamp_ns, max((now_ns - stamp_ns) / _NS, 0.0), reason

    def values(self):
        """Key/values for diagnostics: stamps replaced per stream."""
        return {'stamps_replaced_%s' % stream: count
                for stream, count in sorted(self.replaced.items())}
