"""The sensors' readings between their topics and the estimator (no ROS).

Each sensor of the robot file (:mod:`continuum_statics.core.description.sensors`) delivers
readings at its
own rate (an optical tracker 120 Hz, EM coils 40 Hz) while statics estimates at the encoders'
(1 kHz). A reading is fused once, by its stamp, at the first estimate after it arrived; one
older than ``timeout`` when that estimate comes is not used (a stalled stream must not pin the
shape), nor one stamped further than ``max_offset`` from the clock when it arrives (a tracker
stamped 1970 or by an unsynchronised clock, seconds old or ahead). Only the
readings the estimator used are passed on (:meth:`SensorInbox.used_sources`). What the estimator
made of each
(:class:`~continuum_statics.core.description.sensors.SensorVerdict`)
is counted here per sensor, for ``/diagnostics``: statics, and every node that follows statics'
fused estimate, judge a sensor by this one verdict.
"""
from dataclasses import dataclass, field
import math
import threading

import numpy as np

from continuum_statics.core.description.sensors import SensorReading


@dataclass
class SensorRecord:
    """What one sensor delivered and what became of it."""

    received: int = 0
    used: int = 0
    set_aside: int = 0
    stale: int = 0
    rejected: int = 0  # malformed, non-finite, another frame
    last_arrival: float = None  # s, monotonic
    last_chi2: float = math.nan
    last_reason: str = ''
    last_used: bool = True  # the estimator used its last judged reading
    arrivals: list = field(default_factory=list)  # monotonic times of the last second


class SensorInbox:
    """The newest unread reading of each sensor, and each sensor's record.

    :param names: the robot file's sensor names
    :param timeout: s; a reading older than this at the next estimate is not used
    :param max_offset: s; a reading stamped further than this from the clock is set aside
    """

    def __init__(self, names, timeout, max_offset=1.0):
        self.timeout = float(timeout)
        self.max_offset = float(max_offset)
        self.records = {name: SensorRecord() for name in names}
        self._unread = {}
        self._taken = {}  # name -> source of the readings the last take handed out
        # readings arrive on the subscriptions' thread, the estimate takes them on the intake's:
        # handed over under this lock, never iterated while another thread adds
        self._lock = threading.Lock()

    def put(self, name, position, rotation, stamp, now, sigma=None, source=None,
            clock_now=None):
        """Keep a reading (base frame, m; stamp s) that arrived at ``now`` (monotonic s).

        ``sigma``: the position noise (m) the device reported with it, or None. ``source``: the
        message it came in, passed on once the estimator used it. ``clock_now``: the time of the
        stamps' clock at arrival (s), to judge the stamp by; None: not judged.
        """
        record = self.records[name]
        position = np.asarray(position, dtype=float)
        if position.shape != (3,) or not np.all(np.isfinite(position)) or (
                rotation is not None and not np.all(np.isfinite(rotation))):
            self.reject(name, 'a reading that is not finite')
            return
        record.received += 1
        record.last_arrival = now
        record.arrivals = [t for t in record.arrivals if now - t < 1.0] + [now]
        if stamp is not None and clock_now is not None:
            age = clock_now - stamp
            if not (math.isfinite(age) and abs(age) <= self.max_offset):
                self.reject(name, 'stamped %.3g s %s this clock (max_stamp_offset %g s): '
                            'is its clock synchronised?' % (
                                abs(age), 'before' if age > 0 else 'ahead of', self.max_offset))
                return
        with self._lock:
            self._unread[name] = (SensorReading(position, rotation, stamp, sigma), now, source)

    def reject(self, name, reason, now=None):
        """Count a reading that could not be used at all (its reason goes on diagnostics).

        ``now``: its arrival (monotonic s): a sensor whose readings are refused is not silent.
        """
        record = self.records[name]
        if now is not None:
            record.last_arrival = now
        record.rejected += 1
        record.last_used = False
        record.last_reason = reason

    def take(self, now, stamp=None):
        """Return {name: SensorReading} of the fresh unread readings (then read), or None.

        ``stamp``: the measurement's stamp (s), or None. A reading stamped after it stays unread
        for a later measurement (fused at this one's stamp, its correction would decay over an
        interval it was not yet taken in), for at most half the timeout after its arrival (a
        clock ahead of every measurement's still gets its readings used).
        """
        with self._lock:
            unread, self._unread = self._unread, {}
        fresh, self._taken, later = {}, {}, {}
        for name, (reading, arrival, source) in unread.items():
            if now - arrival > self.timeout:
                self.records[name].stale += 1
            elif (stamp is not None and reading.stamp is not None and reading.stamp > stamp
                  and now - arrival < 0.5 * self.timeout):
                later[name] = (reading, arrival, source)
            else:
                fresh[name] = reading
                self._taken[name] = source
        if later:
            with self._lock:  # a newer reading that arrived meanwhile wins
                for name, entry in later.items():
                    self._unread.setdefault(name, entry)
        return fresh or None

    def used_sources(self, verdicts):
        """Return [(name, source)] of the last taken readings the estimator used."""
        return [(name, self._taken[name]) for name, verdict in (verdicts or {}).items()
                if verdict.used and self._taken.get(name) is not None]

    def judged(self, verdicts):
        """Count the estimator's verdicts ({name: SensorVerdict}) of the readings it was given."""
        for name, verdict in (verdicts or {}).items():
            record = self.records[name]
            record.last_chi2 = verdict.chi2
            record.last_used = verdict.used
            if verdict.used:
                record.used += 1
            else:
                record.set_aside += 1
                record.last_reason = verdict.reason

    def values(self, now):
        """Diagnostic values per sensor: rate, age, innovation chi2, counts, last reason."""
        values = {}
        for name, record in self.records.items():
            age = math.inf if record.last_arrival is None else now - record.last_arrival
            rate = len([t for t in record.arrivals if now - t < 1.0])
            values['sensor_%s' % name] = (
                'rate %d Hz, age %.3g s, chi2 %.3g, used %d, set aside %d, stale %d, '
                'rejected %d%s' % (rate, age, record.last_chi2, record.used, record.set_aside,
                                   record.stale, record.rejected,
                                   ': %s' % record.last_reason if record.last_reason else ''))
        return values

    def problems(self, now):
        """Return WARN text: sensors whose last reading was set aside, or that went silent."""
        notes = []
        for name, record in self.records.items():
            if record.last_arrival is not None and now - record.last_arrival > self.timeout:
                notes.append('sensor %s silent for %.1f s' % (name, now - record.last_arrival))
            elif not record.last_used and record.last_reason:
                notes.append('sensor %s set aside: %s' % (name, record.last_reason))
        return '; '.join(notes)
