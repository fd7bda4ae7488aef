"""RViz markers of the obstacles and contacts (in ``backbone_markers``, next to the rod).

Obstacles as their primitives, semi-transparent grey (namespace ``<node>/obstacles``): a sphere,
a box, a capsule as a cylinder with a sphere on each end, a plane as a thin square of twice the
rod's length around its point nearest the base. Contacts (``<node>/contacts``) as arrows from
the contact point along the normal (from the obstacle towards the body), half the rod's length
for a force of E I / L^2 (the rod's load scale) and in proportion, at least :data:`MIN_ARROW`
and at most the rod's length. Markers no longer drawn (an obstacle cleared, a contact let go) are
deleted by id in the next array.
"""
from geometry_msgs.msg import Point
import numpy as np
from visualization_msgs.msg import Marker

from continuum_statics.core.rod.rotations import rotation_to_quaternion
from continuum_statics.nodes.ros_conversions import set_pose

OBSTACLE_RGBA = (0.55, 0.55, 0.6, 0.35)
CONTACT_RGBA = (0.9, 0.15, 0.1, 1.0)
#: Shortest contact arrow (a contact with a tiny force is still seen), m.
MIN_ARROW = 0.005
#: Thickness of a drawn plane, m.
PLANE_THICKNESS = 5e-4


def _marker(ns, marker_id, marker_type, rgba, header):
    marker = Marker(ns=ns, id=marker_id, type=marker_type, action=Marker.ADD, header=header)
    marker.pose.orientation.w = 1.0
    marker.color.r, marker.color.g, marker.color.b, marker.color.a = (float(v) for v in rgba)
    return marker


def _placed(marker, position, rotation, scale):
    set_pose(marker.pose, np.asarray(position, dtype=float).tolist(),
             rotation_to_quaternion(rotation).tolist())
    marker.scale.x, marker.scale.y, marker.scale.z = (float(v) for v in scale)
    return marker


class ObstacleMarkers:
    """The markers of obstacles and contacts, with deletions of those drawn before.

    :param namespace: prefix of the marker namespaces (the node's name)
    :param length: the rod's length L, m (plane squares and the longest arrow)
    :param load_scale: the force drawn L / 2 long, N (the rod's E I / L^2)
    """

    def __init__(self, namespace, length, load_scale):
        self.obstacles_ns = '%s/obstacles' % namespace
        self.contacts_ns = '%s/contacts' % namespace
        self.length = float(length)
        self.per_newton = 0.5 * self.length / float(load_scale)  # arrow m per N
        self._shown = set()  # (ns, id) of the last array

    def markers(self, header, obstacles, contacts):
        """Return the Markers of ``obstacles`` and ``contacts`` (base frame) and the deletions.

        An empty list when there is nothing to draw and nothing to delete.
        """
        drawn = []
        for obstacle in obstacles:
            drawn += self._obstacle(header, obstacle, len(drawn))
        arrows = [self._arrow(header, contact, k) for k, contact in enumerate(contacts)]
        markers = [m for m in drawn + arrows if m is not None]
        shown = {(m.ns, m.id) for m in markers}
        for ns, marker_id in sorted(self._shown - shown):
            markers.append(Marker(ns=ns, id=marker_id, action=Marker.DELETE, header=header))
        self._shown = shown
        return markers

    def _obstacle(self, header, obstacle, first):
        ns, rgba = self.obstacles_ns, OBSTACLE_RGBA
        kind, size, rotation = obstacle.kind, obstacle.size, obstacle.rotation
        position = np.asarray(obstacle.position, dtype=float)
        if not (np.all(np.isfinite(position)) and np.all(np.isfinite(rotation))):
            return []
        if kind == 'sphere':
            return [_placed(_marker(ns, first, Marker.SPHERE, rgba, header), position, rotation,
                            [2.0 * size[0]] * 3)]
        if kind == 'box':
            return [_placed(_marker(ns, first, Marker.CUBE, rgba, header), position, rotation,
                            size)]
        if kind == 'capsule':
            radius, length = size
            axis = rotation[:, 2] * 0.5 * length
            return [_placed(_marker(ns, first, Marker.CYLINDER, rgba, header), position,
                            rotation, (2.0 * radius, 2.0 * radius, length))] + [
                _placed(_marker(ns, first + k, Marker.SPHERE, rgba, header), position + sign *
                        axis, rotation, [2.0 * radius] * 3) for k, sign in ((1, 1.0), (2, -1.0))]
        # a plane: a thin square around its point nearest the base frame's origin
        side = 2.0 * self.length
        return [_placed(_marker(ns, first, Marker.CUBE, rgba, header), position, rotation,
                        (side, side, PLANE_THICKNESS))]

    def _arrow(self, header, contact, index):
        point = np.asarray(contact.point, dtype=float)
        normal = np.asarray(contact.normal, dtype=float)
        force = float(contact.force)
        if not (np.all(np.isfinite(point)) and np.all(np.isfinite(normal))
                and np.isfinite(force)):
            return None
        marker = _marker(self.contacts_ns, index, Marker.ARROW, CONTACT_RGBA, header)
        length = min(max(force * self.per_newton, MIN_ARROW), self.length)
        tip = point + normal * length
        marker.points = [Point(x=x, y=y, z=z) for x, y, z in (point.tolist(), tip.tolist())]
        marker.scale.x = 0.1 * MIN_ARROW + 0.05 * length  # shaft diameter
        marker.scale.y = 2.0 * marker.scale.x  # head diameter
        marker.scale.z = 0.25 * length  # head length
        return marker
