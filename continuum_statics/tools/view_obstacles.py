"""The view's obstacles and contacts, read from ``backbone_markers`` (statics draws them there).

statics merges the robot file's obstacles with the ``obstacles`` topic's and resolves their frames
(:mod:`continuum_statics.nodes.obstacle_markers`), so the page draws what the model solves with
without a robot file or /tf of its own: spheres, boxes and cylinders (a capsule's parts), in the
markers' grey, semi-transparent, and each contact force as a red segment along its normal.
"""
import numpy as np

#: RViz marker types drawn (visualization_msgs/Marker constants).
CUBE, SPHERE, CYLINDER, ARROW = 1, 2, 3, 0
OBSTACLE_RGB = (140, 140, 153)
CONTACT_RGB = (230, 40, 25)


def _array(values):
    array = np.asarray(values, dtype=float)
    return array if np.all(np.isfinite(array)) else None


def obstacle_shapes(markers):
    """Return [(type, position (3,), wxyz (4,), scale (3,))] of the obstacle markers."""
    shapes = []
    for marker in markers:
        if not marker.ns.endswith('/obstacles') or marker.action != 0 or \
                marker.type not in (CUBE, SPHERE, CYLINDER):
            continue
        p, q, s = marker.pose.position, marker.pose.orientation, marker.scale
        values = _array((p.x, p.y, p.z, q.w, q.x, q.y, q.z, s.x, s.y, s.z))
        if values is not None:
            shapes.append((marker.type, values[:3], values[3:7], values[7:]))
    return shapes


def contact_segments(markers):
    """Return the contact arrows as segments (k, 2, 3): contact point -> along the normal."""
    segments = []
    for marker in markers:
        if marker.ns.endswith('/contacts') and marker.action == 0 and marker.type == ARROW \
                and len(marker.points) == 2:
            points = _array([(p.x, p.y, p.z) for p in marker.points])
            if points is not None:
                segments.append(points)
    return np.reshape(segments, (-1, 2, 3))


class ObstacleDrawing:
    """Keeps the page's obstacle nodes: draws the newest ones, removes those gone."""

    def __init__(self):
        self._names = set()

    def draw(self, scene, shapes, segments):
        """Draw ``shapes`` and contact ``segments`` (:func:`obstacle_shapes`, ...) on ``scene``."""
        names = set()
        for k, (kind, position, wxyz, scale) in enumerate(shapes):
            name = '/obstacles/%d' % k
            place = dict(position=tuple(position), wxyz=tuple(wxyz), opacity=0.35)
            if kind == SPHERE:
                scene.add_icosphere(name, radius=0.5 * scale[0], color=OBSTACLE_RGB, **place)
            elif kind == CUBE:
                scene.add_box(name, color=OBSTACLE_RGB, dimensions=tuple(scale), **place)
            else:
                scene.add_cylinder(name, radius=0.5 * scale[0], height=scale[2],
                                   color=OBSTACLE_RGB, **place)
            names.add(name)
        if len(segments):
            scene.add_line_segments('/contacts', segments, CONTACT_RGB, thickness=0.003)
            names.add('/contacts')
        for name in sorted(self._names - names):
            scene.remove_by_name(name)
        self._names = names
