"""The robot's frames on /tf: which frames, where on the backbone, and their transforms (no ROS).

Every frame is a child of the base frame (a star: ``tf2_echo base_link <robot>_tip`` reads one
transform), at an arc length of the backbone, oriented as the rod's cross-section R(s) there:

- ``<robot name>_tip`` (or ``tip_frame_id``) at the tip, the pose ``tip_pose`` also carries;
- ``<robot name>_section_<k>`` at the end disk of section k (0 = nearest the base);
- with ``tf_disks``, ``<robot name>_disk_<i>`` at guide disk i (base to tip);
- each behind ``frame_prefix`` (e.g. ``arm1/``: two arms from one robot file). The base frame
  is the robot file's, unprefixed: every topic and goal is in it (contract).

The tracker's marker (``tip_marker`` of the robot file, when not zero) is a fixed offset from the
tip frame: ``<tip frame>_marker`` on /tf_static.
"""
import numpy as np

from continuum_statics.core.rod.rotations import rotation_to_quaternion
from continuum_statics.nodes.marker_geometry import nearest_nodes, section_layout


def frames(robot, tip_frame_id='', disks=False, prefix=''):
    """Return (child frame ids, their arc lengths in m), the tip first.

    ``prefix`` (``frame_prefix``, e.g. ``arm1/``) goes before every frame id: two arms from one
    robot file publish frames of their own.
    """
    tip = tip_frame_id or '%s_tip' % robot.name
    names, arc_lengths = [tip], [float(robot.length)]
    _, section_ends = section_layout(robot)
    for k, end in enumerate(section_ends):
        names.append('%s_section_%d' % (robot.name, k))
        arc_lengths.append(float(end))
    if disks:
        for i, s in enumerate(robot.guides):
            names.append('%s_disk_%d' % (robot.name, i))
            arc_lengths.append(float(s))
    return tuple(prefix + name for name in names), np.asarray(arc_lengths)


def marker_frame(tip_frame):
    """Frame id of the tracker's marker on the tip."""
    return tip_frame + '_marker'


class FramePoses:
    """Translations (n, 3) m and quaternions (n, 4) [x, y, z, w] of frames on a shape's grid.

    The nodes nearest the arc lengths are found once per integration grid (guide disks and the
    tip are grid nodes: exact there).
    """

    def __init__(self, arc_lengths):
        self.arc_lengths = np.asarray(arc_lengths, dtype=float)
        self._grid = None
        self._nodes = None

    def of(self, shape):
        """Return the frames' translations and quaternions in the base frame for ``shape``."""
        if self._grid is None or not (shape.s is self._grid or np.array_equal(shape.s,
                                                                              self._grid)):
            self._grid = shape.s
            self._nodes = nearest_nodes(shape.s, self.arc_lengths)
        nodes = self._nodes
        return shape.positions[nodes], rotation_to_quaternion(shape.rotations[nodes])
