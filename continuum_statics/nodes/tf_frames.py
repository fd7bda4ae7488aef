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

Every frame id is used once: :func:`frames` refuses a ``tip_frame_id`` that names another of
these frames, and statics does not start (``tip_frame_id:=base_link`` gave the URDF two
``base_link`` links, no root, and /tf a transform from base_link to itself).
"""
import numpy as np

from continuum_statics.core.rod.rotations import rotation_to_quaternion
from continuum_statics.nodes.marker_geometry import nearest_nodes, section_layout


def frames(robot, tip_frame_id='', disks=False, prefix=''):
    """Return (child frame ids, their arc lengths in m), the tip first.

    ``prefix`` (``frame_prefix``, e.g. ``arm1/``) goes before every frame id: two arms from one
    robot file publish frames of their own.

    :raises ValueError: when two of the frames (with the base frame and the marker's) share an
        id, naming both: a node parameter or the robot file to change, not an invalid URDF
    """
    tip = tip_frame_id or '%s_tip' % robot.name
    names, arc_lengths = [tip], [float(robot.length)]
    roles = ['the tip frame' + (' (tip_frame_id %r)' % tip_frame_id if tip_frame_id else '')]
    _, section_ends = section_layout(robot)
    for k, end in enumerate(section_ends):
        names.append('%s_section_%d' % (robot.name, k))
        arc_lengths.append(float(end))
        roles.append("section %d's end-disk frame" % k)
    if disks:
        for i, s in enumerate(robot.guides):
            names.append('%s_disk_%d' % (robot.name, i))
            arc_lengths.append(float(s))
            roles.append("guide disk %d's frame (tf_disks)" % i)
    names = tuple(prefix + name for name in names)
    owners = [(robot.base_frame_id, 'the base frame (base.frame_id of the robot file)')]
    owners += list(zip(names, roles))
    if np.any(robot.tip_marker):
        owners.append((marker_frame(names[0]), "the tip marker's frame (tip_marker)"))
    _refuse_shared_ids(owners, robot.name)
    return names, np.asarray(arc_lengths)


def _refuse_shared_ids(owners, robot_name):
    """Raise ValueError when one frame id is two frames of ``owners`` [(frame id, role)]."""
    seen = {}
    for frame, role in owners:
        if frame in seen:
            fix = ("choose another tip_frame_id (empty: '%s_tip')" % robot_name
                   if 'tip' in seen[frame] + role
                   else "rename the robot file's name or base.frame_id")
            raise ValueError('frame id %r would be both %s and %s (robot_description would get '
                             'two %r links, /tf two poses for it): %s'
                             % (frame, seen[frame], role, frame, fix))
        seen[frame] = role


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
