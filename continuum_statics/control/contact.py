"""Contact on the tip from a force estimate and its covariance (no ROS).

Contact begins when the estimated force exceeds the threshold with 3-sigma confidence: its
magnitude less three standard deviations along its own direction is above ``threshold``. It
ends when the magnitude itself falls below the threshold; the band between the two is the
hysteresis that keeps noise from toggling it.
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
    :ivar in_contact: the current decision
    """

    def __init__(self, threshold):
        self.threshold = float(threshold)
        self.in_contact = False

    def update(self, force, covariance):
        """Take one estimate; return True when the decision changed."""
        magnitude, sigma = force_along(force, covariance)
        if self.in_contact:
            now = magnitude >= self.threshold
        else:
            now = magnitude - CONFIDENCE * sigma > self.threshold
        changed = now != self.in_contact
        self.in_contact = now
        return changed
