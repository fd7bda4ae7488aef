"""Where a calibration's time goes: wall and CPU seconds per phase (read, scan, fit, ...).

CPU counts this process and the worker processes it reaped during the phase (the forked pools
of :mod:`.pool` are reaped when each closes), so a phase run on every core shows more CPU
than wall time, and a serial one about the same.
"""
import contextlib
import resource
import time


def cpu_seconds():
    """User + system seconds of this process and of its reaped children."""
    own, children = (resource.getrusage(who) for who in (resource.RUSAGE_SELF,
                                                         resource.RUSAGE_CHILDREN))
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


class Phases:
    """Wall and CPU seconds per phase name, in the order first entered (repeats add up)."""

    def __init__(self):
        self.times = {}

    @contextlib.contextmanager
    def __call__(self, name):
        """Time the body as phase ``name``."""
        wall, cpu = time.perf_counter(), cpu_seconds()
        try:
            yield
        finally:
            entry = self.times.setdefault(name, {'wall': 0.0, 'cpu': 0.0})
            entry['wall'] += time.perf_counter() - wall
            entry['cpu'] += cpu_seconds() - cpu

    def add(self, other):
        """Add another :class:`Phases`' (or its ``times``') seconds into these."""
        for name, entry in getattr(other, 'times', other).items():
            mine = self.times.setdefault(name, {'wall': 0.0, 'cpu': 0.0})
            mine['wall'] += entry['wall']
            mine['cpu'] += entry['cpu']

    def rounded(self):
        """Return the summary's ``phases``: name -> {wall, cpu} seconds, to 0.01 s."""
        return {name: {key: round(value, 2) for key, value in entry.items()}
                for name, entry in self.times.items()}


def format_phases(phases):
    """One line per phase of a summary's ``phases``: wall and CPU seconds, and the total."""
    lines = ['  %-9s %7s %7s' % ('phase', 'wall s', 'CPU s')]
    for name, entry in phases.items():
        lines.append('  %-9s %7.2f %7.2f' % (name, entry['wall'], entry['cpu']))
    lines.append('  %-9s %7.2f %7.2f' % ('total', sum(e['wall'] for e in phases.values()),
                                         sum(e['cpu'] for e in phases.values())))
    return '\n'.join(lines)
