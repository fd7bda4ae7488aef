"""``robot_description``: the robot file's geometry as URDF, its links placed by statics' /tf.

RViz's RobotModel display and Foxglove's 3-D panel draw a URDF's links where /tf puts them.
Continuum-robot descriptions usually fake the rod with a chain of many rigid joints; here every
link is a frame statics already publishes (:mod:`.tf_frames`), joined to the base by a
``floating`` joint (robot_state_publisher publishes nothing for those), so the model shows the
estimated robot itself:

- the base frame (``base.frame_id``): the clamp, a cylinder behind the rod's start;
- ``<robot name>_section_<k>``: the end disk of section k, a cylinder marked ``end_disk``;
- with ``tf_disks``, ``<robot name>_disk_<i>``: every other guide disk, a cylinder;
- ``<robot name>_tip`` (or ``tip_frame_id``): the tip, a small sphere.

A disk's cylinder lies in its frame's xy plane (the frame's z is along the rod), as URDF draws
cylinders about z. Published once by statics as std_msgs/String, reliable and transient local,
like robot_state_publisher's ``robot_description``.
"""
import math
from xml.etree import ElementTree

import numpy as np

from continuum_statics.nodes.marker_geometry import section_layout
from continuum_statics.nodes.tf_frames import frames

#: Guide disks, m: thickness (as the markers draw them) and the clamp's length behind s = 0.
DISK_THICKNESS = 0.002
CLAMP_LENGTH = 0.01
#: Material name -> RGBA of the description's parts.
MATERIALS = {'clamp': (0.35, 0.35, 0.38, 1.0), 'guide_disk': (0.8, 0.8, 0.82, 1.0),
             'end_disk': (0.95, 0.55, 0.1, 1.0), 'tip': (0.9, 0.1, 0.1, 1.0)}


def disk_diameter(robot):
    """Guide-disk diameter to draw, m: the outermost cable hole plus 3 mm of rim on each side."""
    holes = np.asarray(robot.cable_offsets, dtype=float).reshape(-1, 3)
    return 2.0 * float(np.max(np.linalg.norm(holes, axis=1), initial=0.005)) + 0.006


def rotation_to_rpy(rotation):
    """URDF roll, pitch, yaw (rad) of a rotation matrix: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    r = np.asarray(rotation, dtype=float)
    pitch = math.asin(max(-1.0, min(1.0, -r[2, 0])))
    if abs(r[2, 0]) < 1.0 - 1e-12:
        return math.atan2(r[2, 1], r[2, 2]), pitch, math.atan2(r[1, 0], r[0, 0])
    return math.atan2(-r[1, 2], r[1, 1]), pitch, 0.0  # gimbal lock: yaw folded into roll


def _numbers(values):
    return ' '.join('%.9g' % (float(v) + 0.0) for v in values)  # + 0.0: no '-0'


def _visual(link, geometry, size, material, xyz=(0.0, 0.0, 0.0), rpy=(0.0, 0.0, 0.0)):
    visual = ElementTree.SubElement(link, 'visual')
    ElementTree.SubElement(visual, 'origin', xyz=_numbers(xyz), rpy=_numbers(rpy))
    shape = ElementTree.SubElement(ElementTree.SubElement(visual, 'geometry'), geometry,
                                   {key: '%.9g' % value for key, value in size.items()})
    ElementTree.SubElement(visual, 'material', name=material)
    return shape


def link_names(robot, tip_frame_id='', disks=False, prefix=''):
    """Return the description's links: the base frame, then the /tf frames statics publishes.

    Guide disks that are a section's end disk are drawn by their ``section`` link only;
    ``prefix`` is statics' ``frame_prefix`` (its frames', not the base frame's).
    """
    names, arc_lengths = frames(robot, tip_frame_id, disks, prefix)
    _, section_ends = section_layout(robot)
    own = len(prefix) + len(robot.name)  # what follows the robot's name in a frame id
    keep = [name for name, s in zip(names, arc_lengths)
            if '_disk_' not in name[own:]
            or not np.any(np.isclose(section_ends, s, atol=1e-9))]
    return (robot.base_frame_id,) + tuple(keep)


def robot_urdf(robot, tip_frame_id='', disks=False, prefix=''):
    """Return the URDF (str) of ``robot``'s base and disks, links named as statics' /tf frames.

    :param robot: a :class:`~continuum_statics.core.robot.Robot`
    :param tip_frame_id: statics' ``tip_frame_id`` parameter (empty: ``<robot name>_tip``)
    :param disks: statics' ``tf_disks`` parameter: one link per guide disk too
    :param prefix: statics' ``frame_prefix`` parameter (before every link but the base)
    """
    root = ElementTree.Element('robot', name=robot.name)
    for name, rgba in MATERIALS.items():
        ElementTree.SubElement(ElementTree.SubElement(root, 'material', name=name), 'color',
                               rgba=_numbers(rgba))
    radius = disk_diameter(robot) / 2.0
    names = link_names(robot, tip_frame_id, disks, prefix)
    base = ElementTree.SubElement(root, 'link', name=names[0])
    # the clamp: the rod leaves it at base.position along the base rotation's z axis
    rotation = np.asarray(robot.base_rotation, dtype=float)
    centre = np.asarray(robot.base_position, dtype=float) - rotation[:, 2] * CLAMP_LENGTH / 2.0
    _visual(base, 'cylinder', {'radius': radius, 'length': CLAMP_LENGTH}, 'clamp', centre,
            rotation_to_rpy(rotation))
    for name in names[1:]:
        link = ElementTree.SubElement(root, 'link', name=name)
        if name == names[1]:  # frames() lists the tip first
            _visual(link, 'sphere', {'radius': 0.6 * DISK_THICKNESS}, 'tip')
        else:
            marked = '_section_' in name[len(prefix) + len(robot.name):]
            _visual(link, 'cylinder', {'radius': radius, 'length': DISK_THICKNESS},
                    'end_disk' if marked else 'guide_disk')
        joint = ElementTree.SubElement(root, 'joint', name=name + '_joint', type='floating')
        ElementTree.SubElement(joint, 'parent', link=names[0])
        ElementTree.SubElement(joint, 'child', link=name)
    ElementTree.indent(root)
    return '<?xml version="1.0"?>\n' + ElementTree.tostring(root, encoding='unicode') + '\n'


def publish_robot_description(node, robot, tip_frame_id='', disks=False, prefix=''):
    """Create the latched ``robot_description`` publisher on ``node``, publish once, return it."""
    from std_msgs.msg import String

    from continuum_statics.nodes.qos import LATCHED_QOS

    publisher = node.create_publisher(String, 'robot_description', LATCHED_QOS)
    publisher.publish(String(data=robot_urdf(robot, tip_frame_id, disks, prefix)))
    return publisher
