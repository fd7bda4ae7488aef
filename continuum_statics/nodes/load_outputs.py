"""statics' tip-load outputs: the robot file's ``load_model`` estimated with the shape (issue 43).

With ``load_model`` in the robot file the tip load is part of statics' fused state
(:mod:`~continuum_statics.core.estimation.state_estimation`): every reading is judged once and
counted once, for the shape and the load together. statics then publishes what the
tip_load_estimator node publishes for other robot files, on the same topics:

- ``tip_wrench_estimate`` (geometry_msgs/WrenchStamped, base frame, the estimate's stamp), with
  the covariance outputs (at most ``covariance_rate`` Hz); tip_controller reads it with
  ``tip_wrench_source: estimate``;
- ``tip_contact`` (std_msgs/Bool, latched): True while the force exceeds ``contact_threshold``
  with 3-sigma confidence for ``contact_min_time`` (:class:`~continuum_statics.control.contact.
  ContactDetector`), with a WARN diagnostic;
- on /diagnostics: the force and its standard deviations (a payload's mass with 'weight').
"""
import math
import time

from geometry_msgs.msg import WrenchStamped
import numpy as np
from std_msgs.msg import Bool

from continuum_statics.control.contact import ContactDetector, force_along
from continuum_statics.control.health import OK, WARN
from continuum_statics.core.estimation.load_estimation import plausible_tip_load
from continuum_statics.core.estimation.state_estimation import cables_settling
from continuum_statics.nodes.qos import LATCHED_QOS


class TipLoadOutputs:
    """Publishers of the fused tip load and the contact decision made on it."""

    def __init__(self, node, robot, threshold, min_time):
        self.robot = robot
        self._logger = node.get_logger()
        self.contact = ContactDetector(self.threshold_or_default(threshold), min_time)
        self._wrench_pub = node.create_publisher(WrenchStamped, 'tip_wrench_estimate', 10)
        self._contact_pub = node.create_publisher(Bool, 'tip_contact', LATCHED_QOS)
        self._contact_pub.publish(Bool(data=False))
        self._last = None  # (wrench (6,), covariance (6, 6)) last published

    def threshold_or_default(self, threshold):
        """contact_threshold (N), or a tenth of the rod's plausible tip load when 0."""
        return threshold or plausible_tip_load(self.robot)[0] / 10.0

    def publish(self, estimate, header):
        """Publish the load of a fused ``estimate`` (``header``: its stamp, base frame)."""
        wrench, covariance = estimate.tip_wrench, estimate.tip_wrench_covariance
        if wrench is None or not (np.all(np.isfinite(wrench))
                                  and np.all(np.isfinite(covariance))):
            return  # never anything non-finite
        msg = WrenchStamped(header=header)
        msg.wrench.force.x, msg.wrench.force.y, msg.wrench.force.z = (float(v)
                                                                      for v in wrench[:3])
        msg.wrench.torque.x, msg.wrench.torque.y, msg.wrench.torque.z = (float(v)
                                                                         for v in wrench[3:])
        self._wrench_pub.publish(msg)
        self._last = (wrench, covariance)
        # contact never begins while the cables move or settle (a moving rod looks loaded), as
        # the tip_load_estimator node's
        if self.contact.update(wrench[:3], covariance, time.monotonic(),
                               not cables_settling(estimate.unmodelled)):
            self._contact_pub.publish(Bool(data=self.contact.in_contact))
            magnitude, sigma = force_along(wrench[:3], covariance)
            if self.contact.in_contact:
                self._logger.warning('contact on the tip: %.3g N (sigma %.2g N) above '
                                     'contact_threshold %.3g N'
                                     % (magnitude, sigma, self.contact.threshold))
            else:
                self._logger.info('contact ended: %.3g N' % magnitude)

    def diagnose(self, level, message, values):
        """Add the load's values to ``values``; return the status (WARN while in contact)."""
        values['load_model'] = self.robot.load_model.name
        values['in_contact'] = self.contact.in_contact
        values['contact_threshold_n'] = self.contact.threshold
        if self._last is None:
            return level, message
        wrench, covariance = self._last
        sigma = np.sqrt(np.diag(covariance))
        values['force_n'] = ' '.join('%.4g' % v for v in wrench[:3])
        values['force_sigma_n'] = ' '.join('%.3g' % v for v in sigma[:3])
        if self.robot.load_model.name == 'wrench':
            values['moment_nm'] = ' '.join('%.4g' % v for v in wrench[3:])
            values['moment_sigma_nm'] = ' '.join('%.3g' % v for v in sigma[3:])
        if self.robot.load_model.name == 'weight':
            g = float(np.linalg.norm(self.robot.gravity))
            values['mass_kg'] = '%.5g' % (float(np.linalg.norm(wrench[:3])) / g
                                          * math.copysign(1.0, wrench[:3] @ self.robot.gravity))
            values['mass_sigma_kg'] = '%.3g' % (math.sqrt(float(
                self.robot.gravity @ covariance[:3, :3] @ self.robot.gravity)) / g ** 2)
        if self.contact.in_contact and level == OK:
            return WARN, 'contact on the tip: %.3g N' % force_along(wrench[:3], covariance)[0]
        return level, message
