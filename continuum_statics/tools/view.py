"""``python -m continuum_statics view``: the live robot in a web browser (viser).

Serves a 3-D page (``--port``, default 8080, on ``--host``) with the live backbone (``backbone``),
guide disks and cables (``backbone_markers``; cables coloured by the tension ``cable_states``
reports, blue 0 N to red ``--max-tension``, grey when no tension is measured), the obstacles and
contact forces statics draws there (:mod:`.view_obstacles`), the tip trail
(``tip_pose``), the goal in force (``tip_goal_active``) and every node's status
(``/diagnostics``). A draggable gizmo (or the goal fields) and the *Send goal* button publish a
tip goal on ``tip_goal_pose``. The fields and gizmo follow the goal in force, whoever sent it,
unless they hold an edit not sent yet (:func:`follow_goal`). Until a topic has arrived the page
says what it waits for.
Works wherever the page opens: no RViz needed.
"""
import argparse
from collections import deque
import math
import re
import sys
import threading
import time

import numpy as np

from continuum_statics.tools.view_obstacles import (
    ObstacleDrawing,
    contact_segments,
    obstacle_shapes,
)

#: Tip poses kept in the trail.
TRAIL = 300
#: Page refresh, Hz.
REFRESH_HZ = 10.0
BACKBONE_RGB = (217, 140, 38)
GOAL_RGB = (220, 30, 30)
#: The goal fields' resolution, decimals of a metre (0.1 mm).
FIELD_DECIMALS = 4
#: Fields further than this from what the view last put there hold the user's edit, m.
EDIT_TOLERANCE = 0.5 * 10.0 ** -FIELD_DECIMALS


class LiveState:
    """The newest of every topic, written by the ROS thread, read by the page thread."""

    def __init__(self):
        self.lock = threading.Lock()
        self.backbone = None  # (N, 3) m
        self.frame_id = ''
        self.disks = []  # [(position (3,), quaternion xyzw (4,), diameter m)]
        self.cables = []  # [(name, (k, 3) points)]
        self.obstacles, self.contacts = [], np.zeros((0, 2, 3))  # from backbone_markers
        self.tensions = {}  # cable name -> N
        self.trail = deque(maxlen=TRAIL)
        self.goal = None  # (3,) m
        self.frames = {}  # section-end frames from /tf: child id -> (position (3,), xyzw (4,))
        self.statuses = {}  # node -> (level, message)
        self.version = 0

    def update(self, **values):
        """Replace some fields and mark the state as changed."""
        with self.lock:
            for key, value in values.items():
                setattr(self, key, value)
            self.version += 1


def _finite(array):
    array = np.asarray(array, dtype=float)
    return array if np.all(np.isfinite(array)) else None


def ros_thread(namespace, state, outbox, stop):
    """Subscribe to the robot's topics; publish the goals the page queues in ``outbox``."""
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PoseStamped
    from nav_msgs.msg import Path
    import rclpy
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import JointState
    from visualization_msgs.msg import Marker, MarkerArray

    from continuum_statics.nodes.qos import COMMAND_QOS, LATCHED_QOS

    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('view', namespace=namespace, context=context)
    prefix = namespace.strip('/')

    def on_backbone(msg):
        points = _finite([(p.pose.position.x, p.pose.position.y, p.pose.position.z)
                          for p in msg.poses])
        if points is not None and len(points) >= 2:
            state.update(backbone=points, frame_id=msg.header.frame_id)

    def on_markers(msg):
        disks, cables = [], []
        for marker in msg.markers:
            if marker.type == Marker.CYLINDER and marker.ns.endswith('guides'):
                p, q = marker.pose.position, marker.pose.orientation
                disks.append((np.array([p.x, p.y, p.z]), np.array([q.x, q.y, q.z, q.w]),
                              float(marker.scale.x)))
            elif marker.type == Marker.LINE_STRIP and marker.ns.endswith('cables'):
                points = _finite([(p.x, p.y, p.z) for p in marker.points])
                if points is not None and len(points) >= 2:
                    cables.append((marker.id, points))
        state.update(disks=disks, cables=cables, obstacles=obstacle_shapes(msg.markers),
                     contacts=contact_segments(msg.markers))

    def on_states(msg):
        if len(msg.effort) == len(msg.name):
            state.update(tensions=dict(zip(range(len(msg.name)), msg.effort)))

    def on_tip(msg):
        p = msg.pose.position
        point = _finite((p.x, p.y, p.z))
        if point is not None:
            with state.lock:
                state.trail.append(point)
                state.version += 1

    def on_goal(msg):
        p = msg.pose.position
        point = _finite((p.x, p.y, p.z))
        if point is not None:
            state.update(goal=point)

    def on_tf(msg):
        frames = dict(state.frames)
        for transform in msg.transforms:
            if re.search(r'_section_\d+$', transform.child_frame_id):
                t, q = transform.transform.translation, transform.transform.rotation
                pose = _finite((t.x, t.y, t.z, q.x, q.y, q.z, q.w))
                if pose is not None:
                    frames[transform.child_frame_id] = (pose[:3], pose[3:])
        state.update(frames=frames)

    def on_diagnostics(msg):
        statuses = dict(state.statuses)
        for status in msg.status:
            if not prefix or status.name.startswith(prefix + '/'):
                level = status.level[0] if isinstance(status.level, bytes) else status.level
                statuses[status.name] = (int(level), status.message)
        state.update(statuses=statuses)

    node.create_subscription(Path, 'backbone', on_backbone, LATCHED_QOS)
    node.create_subscription(MarkerArray, 'backbone_markers', on_markers, LATCHED_QOS)
    node.create_subscription(JointState, 'cable_states', on_states, qos_profile_sensor_data)
    node.create_subscription(PoseStamped, 'tip_pose', on_tip, LATCHED_QOS)
    node.create_subscription(PoseStamped, 'tip_goal_active', on_goal, LATCHED_QOS)
    node.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics, 10)
    try:  # the section ends on /tf (statics publishes them; tf2_msgs is built by make venv)
        from tf2_msgs.msg import TFMessage

        from continuum_statics.nodes.qos import TF_QOS
        node.create_subscription(TFMessage, '/tf', on_tf, TF_QOS)
    except ImportError:
        pass
    goals = node.create_publisher(PoseStamped, 'tip_goal_pose', COMMAND_QOS)
    executor = rclpy.executors.SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        while not stop.is_set():
            executor.spin_once(timeout_sec=0.02)
            while outbox:
                position, frame_id = outbox.popleft()
                msg = PoseStamped()
                msg.header.frame_id = frame_id
                msg.header.stamp = node.get_clock().now().to_msg()
                msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = (
                    float(v) for v in position)
                msg.pose.orientation.w = 1.0
                goals.publish(msg)
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def field_value(position):
    """Return ``position`` (m) as the goal fields show it: a tuple rounded to 0.1 mm."""
    return tuple(round(float(v), FIELD_DECIMALS) for v in position)


def follow_goal(fields, synced, goal):
    """Return where the goal fields go when the goal in force becomes ``goal``, or None.

    The fields follow goals from any client (service, action, teleop, another view) while they
    show what the view itself last put there (``synced``: the tip, a goal, or the goal just
    sent); a difference is the user's edit, not sent yet, and it is kept rather than
    overwritten. All positions in m, base frame.
    """
    if np.max(np.abs(np.subtract(fields, synced))) > EDIT_TOLERANCE:
        return None
    return field_value(goal)


def tension_colours(values, max_tension):
    """RGB (k, 3) uint8, blue at 0 N to red at ``max_tension``; grey for unknown (NaN)."""
    values = np.asarray(values, dtype=float)
    share = np.clip(values / max_tension, 0.0, 1.0)
    colours = np.stack([255 * share, 60 + 0 * share, 255 * (1.0 - share)], axis=-1)
    colours[~np.isfinite(values)] = (150, 150, 150)
    return colours.astype(np.uint8)


class Page:
    """The viser scene and panel, redrawn from a :class:`LiveState`."""

    def __init__(self, server, state, outbox, max_tension):
        self.server, self.state, self.outbox = server, state, outbox
        self.max_tension = max_tension
        self.seen = -1
        self.gizmo = None
        self._goal_seen = None  # the goal in force the fields were last offered
        gui = server.gui
        self.status = gui.add_markdown('**waiting for backbone** (is statics running?)')
        self.goal_field = gui.add_vector3('goal (m, base frame)', (0.0, 0.0, 0.0), step=0.001)
        # what the view last put into the goal fields: they differ from it when the user edits
        self.synced = field_value(self.goal_field.value)
        self.send = gui.add_button('Send goal')
        self.send.on_click(lambda _: self.send_goal())
        self.goal_field.on_update(lambda _: self._move_gizmo(self.goal_field.value))
        server.scene.set_up_direction('+z')  # REP-103 base frame
        self._placed = set()  # clients whose camera looks at the robot
        self._obstacles = ObstacleDrawing()
        server.scene.add_grid('/grid', width=0.6, height=0.6, cell_size=0.05)

    @staticmethod
    def _place_camera(client):
        """Look at the robot (tens of cm) rather than viser's default metres away."""
        client.camera.position = (0.45, -0.45, 0.35)
        client.camera.look_at = (0.0, 0.0, 0.15)
        client.camera.up_direction = (0.0, 0.0, 1.0)

    def send_goal(self):
        """Queue the goal the fields (and the gizmo) show as a tip goal."""
        goal = np.asarray(self.goal_field.value, dtype=float)
        if np.all(np.isfinite(goal)):
            self.synced = tuple(self.goal_field.value)  # sent: no longer an edit to keep
            self.outbox.append((goal, self.state.frame_id or 'base_link'))

    def _set_fields(self, position):
        """Put ``position`` (m) into the goal fields and the gizmo, as not edited."""
        self.synced = field_value(position)
        self.goal_field.value = self.synced
        self._move_gizmo(self.synced)

    def _move_gizmo(self, position):
        if self.gizmo is not None:
            self.gizmo.position = tuple(float(v) for v in position)

    def _on_drag(self, _):
        self.goal_field.value = field_value(self.gizmo.position)

    def refresh(self):
        """Redraw what changed."""
        for client_id, client in self.server.get_clients().items():
            if client_id not in self._placed:
                self._placed.add(client_id)
                self._place_camera(client)
        state = self.state
        with state.lock:
            if state.version == self.seen:
                return
            self.seen = state.version
            backbone = state.backbone
            disks, cables = list(state.disks), list(state.cables)
            tensions, trail = dict(state.tensions), np.array(state.trail)
            goal, statuses = state.goal, dict(state.statuses)
            frames = dict(state.frames)
            obstacles, contacts = list(state.obstacles), state.contacts
        scene = self.server.scene
        self._obstacles.draw(scene, obstacles, contacts)
        if backbone is not None:
            segments = np.stack([backbone[:-1], backbone[1:]], axis=1)
            scene.add_line_segments('/robot/backbone', segments, BACKBONE_RGB, thickness=0.008)
            if self.gizmo is None:  # the goal gizmo starts at the goal in force, else the tip
                start = field_value(backbone[-1] if goal is None else goal)
                self.gizmo = scene.add_transform_controls('/goal_gizmo', scale=0.08,
                                                          position=start,
                                                          disable_rotations=True)
                self.gizmo.on_update(self._on_drag)
                self._set_fields(start)
                self._goal_seen = goal
        if goal is not None and goal is not self._goal_seen:  # a new goal (a new array each)
            self._goal_seen = goal
            target = follow_goal(self.goal_field.value, self.synced, goal)
            if target is not None:
                self._set_fields(target)
        for i, (position, quaternion, diameter) in enumerate(disks):
            x, y, z, w = quaternion
            scene.add_cylinder('/robot/disk_%d' % i, radius=0.5 * diameter, height=0.002,
                               color=(120, 120, 120), wxyz=(w, x, y, z),
                               position=tuple(position), opacity=0.8)
        for index, points in cables:
            colour = tension_colours([tensions.get(index, math.nan)], self.max_tension)[0]
            segments = np.stack([points[:-1], points[1:]], axis=1)
            scene.add_line_segments('/robot/cable_%d' % index, segments, tuple(colour),
                                    thickness=0.0015)
        for child, (position, (x, y, z, w)) in frames.items():
            scene.add_frame('/robot/frames/' + child, wxyz=(w, x, y, z), position=tuple(position),
                            axes_length=0.025, axes_radius=0.0012)
        if len(trail) >= 2:
            scene.add_point_cloud('/trail', trail, (40, 120, 220), point_size=0.003)
        if goal is not None:
            scene.add_icosphere('/goal', radius=0.006, color=GOAL_RGB, position=tuple(goal))
        lines = ['waiting for **backbone** (is statics running?)' if backbone is None else
                 'tip **%.1f %.1f %.1f** mm' % tuple(backbone[-1] * 1e3)]
        if goal is not None and follow_goal(self.goal_field.value, self.synced, goal) is None:
            lines.append('goal fields: your edit, not sent (goal in force **%.1f %.1f %.1f** mm)'
                         % tuple(np.asarray(goal) * 1e3))
        if not cables:
            lines.append('waiting for **backbone_markers**')
        if not tensions:
            lines.append('cables grey: no measured tensions')
        names = ('OK', 'WARN', 'ERROR', 'STALE')
        lines += ['%s: %s %s' % (name.split('/')[-1], names[min(level, 3)], message)
                  for name, (level, message) in sorted(statuses.items())]
        self.status.content = '\n\n'.join(lines)


def main(argv=None):
    """Serve the page until Ctrl-C; returns the exit code."""
    parser = argparse.ArgumentParser(prog='python -m continuum_statics view',
                                     description=__doc__.splitlines()[0])
    parser.add_argument('--namespace', default='continuum', help='robot namespace')
    parser.add_argument('--port', type=int, default=8080, help='web page port')
    parser.add_argument('--host', default='127.0.0.1', help='address to serve on '
                        '(0.0.0.0: every interface)')
    parser.add_argument('--max-tension', type=float, default=20.0,
                        help='cable tension drawn red, N')
    options = parser.parse_args(argv)
    import viser

    state, outbox, stop = LiveState(), deque(), threading.Event()
    thread = threading.Thread(target=ros_thread, args=(options.namespace, state, outbox, stop),
                              daemon=True, name='view_ros')
    thread.start()
    server = viser.ViserServer(host=options.host, port=options.port, verbose=False)
    page = Page(server, state, outbox, options.max_tension)
    # viser moves to the next free port when the asked one is taken: say which it is
    print('view: http://%s:%d (namespace /%s); Ctrl-C to stop'
          % (options.host, server.get_port(), options.namespace.strip('/')), flush=True)
    try:
        while thread.is_alive():
            page.refresh()
            time.sleep(1.0 / REFRESH_HZ)
    except KeyboardInterrupt:
        pass
    finally:
        stop.set()
        thread.join(timeout=2.0)
        server.stop()
    return 0


if __name__ == '__main__':
    sys.exit(main())
