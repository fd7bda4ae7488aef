"""Contact on the tip from a force estimate and its covariance (no ROS).

Contact begins when the estimated force exceeds the threshold with 3-sigma confidence: its
magnitude less three standard deviations along its own direction is above ``threshold``. It
ends when the magnitude itself falls below the threshold; the band between the two is the
hysteresis that keeps noise from toggling it. Either change takes effect only once the new
decision has held for ``min_time`` seconds of successive estimates (one outlier or a transient
does not toggle it), and contact never begins on an estimate marked unreliable (the cables
moving: the statics model has no dynamics, so a moving rod looks loaded).
"""
import math

import numpy as np

#: Standard deviations of confidence asked before contact is declared.
CONFIDENCE = 3.0


def force_along(force, covariance):
    """Return (|F| N, sigma of |F| N): the spread along the force's own direction."""
    force = np.asarray(force, dtype=float)
    magnitude = float(np.linalg.norm(force))
    if magnitude == 0.0:
        return 0.0, math.sqrt(float(np.max(np.diag(covariance)[:3])))
    direction = force / magnitude
    return magnitude, math.sqrt(max(float(direction @ covariance[:3, :3] @ direction), 0.0))


class ContactDetector:
    """Whether the tip touches something, from successive force estimates.

    :ivar threshold: N, a force below this is not contact
    :ivar min_time: s a new decision must hold before it is taken
    :ivar in_contact: the current decision
    """

    def __init__(self, threshold, min_time=0.0):
        self.threshold = float(threshold)
        self.min_time = float(min_time)
        self.in_contact = False
        self._since = None  # monotonic s since when the estimates disagree with the decision

    def update(self, force, covariance, now=0.0, reliable=True):
        """Take one estimate at ``now`` (monotonic s); return True when the decision changed."""
        magnitude, sigma = force_along(force, covariance)
        if self.in_contact:
            wanted = magnitude >= self.threshold
        else:
            wanted = reliable and magnitude - CONFIDENCE * sigma > self.threshold
        if wanted == self.in_contact:
            self._since = None
            return False
        if self._since is None:
            self._since = now
        if now - self._since < self.min_time:
            return False
        self.in_contact, self._since = wanted, None
        return True

    def hold(self):
        """Start a pending change over (an estimate was set aside)."""
        self._since = None
