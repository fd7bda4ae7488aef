"""The ``obstacles`` topic of a node (statics, tip_controller): merged, base frame, versioned.

Subscribes ``obstacles`` (continuum_statics_interfaces/msg/Obstacles; reliable, transient local:
a latched sender's last message reaches a node started later) in the node's namespace, merges it
with the robot file's obstacles (:mod:`.obstacle_set`: a name given again replaces it, a message
without names clears the topic's) and keeps :attr:`ObstacleTopic.current`, the merged tuple in the
base frame, with :attr:`~ObstacleTopic.version` counting its changes. ``on_change(current)`` is
called after each change, from the executor (in order: one callback group for every input here).

A message in another frame than the base frame is mapped through /tf and /tf_static, which are
subscribed only while some topic obstacle is in such a frame (statics itself publishes /tf at the
measurement rate). An obstacle whose frame has no chain of transforms to the base frame is left
out and, after :data:`FRAME_GRACE` (the transforms of a frame just subscribed take a moment to
arrive), refused by name (WARN in the log and on /diagnostics, ``obstacles_refused``); it is
taken as soon as a transform completes the chain. A malformed entry (:mod:`.obstacle_messages`)
is refused by name at once and leaves the obstacle of that name as it was.
"""
import threading
import time

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup

from continuum_statics.nodes.diagnostics_util import OK, WARN
from continuum_statics.nodes.obstacle_messages import obstacles_from_msg, transforms_of
from continuum_statics.nodes.obstacle_set import FrameTree, ObstacleSet, same_obstacles
from continuum_statics.nodes.qos import OBSTACLES_QOS, TF_QOS, TF_STATIC_QOS
from continuum_statics.nodes.timers import steady_timer

#: How long an obstacle's frame may lack a chain to the base frame before it is refused, s.
FRAME_GRACE = 1.0


def load_obstacles_type():
    """Return the Obstacles message type, or None when the interfaces package is not built."""
    try:
        from continuum_statics_interfaces.msg import Obstacles
    except ImportError:
        return None
    return Obstacles


class ObstacleTopic:
    """The obstacles a node solves with: the robot file's and the ``obstacles`` topic's.

    :param node: the node (subscriptions, logger)
    :param robot: its robot (``obstacles``, ``base_frame_id``)
    :param on_change: ``on_change(current)`` after every change of :attr:`current` (or None)
    """

    def __init__(self, node, robot, on_change=None):
        self._node = node
        self._log = node.get_logger()
        self.base_frame_id = robot.base_frame_id
        self._set = ObstacleSet(robot.obstacles, robot.base_frame_id)
        self._tree = FrameTree()
        self._lock = threading.Lock()  # the executor's callbacks against diagnose()
        self._group = MutuallyExclusiveCallbackGroup()
        self.on_change = on_change
        #: the merged obstacles, base frame (a new tuple at every change)
        self.current = tuple(robot.obstacles)
        self.version = 0
        self.refused = {}  # name -> why its last entry was refused (malformed)
        self.unresolved = {}  # name -> (frame with no chain to the base frame, since when)
        self._warned = set()  # unresolved names warned about
        self.received = 0  # messages taken
        self._tf = []  # the /tf and /tf_static subscriptions while a frame needs them
        msg_type = load_obstacles_type()
        if msg_type is None:
            self._log.warning('continuum_statics_interfaces is not built: no obstacles topic '
                              "(only the robot file's obstacles)")
            return
        node.create_subscription(msg_type, 'obstacles', self._on_obstacles, OBSTACLES_QOS,
                                 callback_group=self._group)
        steady_timer(node, 0.25 * FRAME_GRACE, self._warn_unresolved, self._group)

    @property
    def follows_tf(self):
        """True while /tf and /tf_static are subscribed (an obstacle is in another frame)."""
        return bool(self._tf)

    # -- inputs ----------------------------------------------------------------------------
    def _on_obstacles(self, msg):
        try:
            obstacles, refused = obstacles_from_msg(msg)
        except ValueError as error:
            self._log.warning('obstacles message refused: %s' % error)
            with self._lock:
                self.refused['(message)'] = str(error)
            return
        for name, reason in refused.items():
            self._log.warning('obstacle %r refused: %s' % (name, reason))
        with self._lock:
            self.received += 1
            self.refused.pop('(message)', None)
            if not msg.names:
                self._set.apply([])
                self.refused.clear()
            else:
                self._set.apply(obstacles)
                for obstacle in obstacles:
                    self.refused.pop(obstacle.name, None)
                self.refused.update(refused)
            outcome = self._update()
        self._follow_frames()
        self._report(*outcome)

    def _on_tf(self, msg):
        with self._lock:
            changed = False
            for parent, child, rotation, translation in transforms_of(msg):
                changed |= self._tree.set(parent, child, rotation, translation)
            if not changed:
                return
            outcome = self._update()
        self._report(*outcome)

    # -- the merged set --------------------------------------------------------------------
    def _update(self):
        """Resolve the set (under the lock); return (current or None, names resolved now).

        ``current`` when it changed; the names are those refused for their frame before.
        """
        merged, unresolved = self._set.resolve(self._tree)
        now = time.monotonic()
        resolved = sorted(name for name in self._warned if name not in unresolved)
        self.unresolved = {name: self.unresolved[name] if self.unresolved.get(
            name, (None,))[0] == frame else (frame, now) for name, frame in unresolved.items()}
        self._warned &= set(self.unresolved)
        if same_obstacles(merged, self.current):
            return None, resolved
        self.current = merged
        self.version += 1
        return merged, resolved

    def _report(self, changed, resolved):
        for name in resolved:
            if any(o.name == name for o in self.current):
                self._log.info('obstacle %r taken: its frame reaches %r now'
                               % (name, self.base_frame_id))
        if changed is not None:
            self._log.info('obstacles: %s' % (', '.join(o.name for o in changed) or 'none'))
            if self.on_change is not None:
                self.on_change(changed)

    def _late(self):
        """Return {name: frame} of the obstacles unresolved for longer than the grace."""
        now = time.monotonic()
        return {name: frame for name, (frame, since) in self.unresolved.items()
                if now - since >= FRAME_GRACE}

    def _warn_unresolved(self):
        with self._lock:
            late = {name: frame for name, frame in self._late().items()
                    if name not in self._warned}
            self._warned.update(late)
        for name, frame in sorted(late.items()):
            self._log.warning('obstacle %r refused: %s' % (name, self._frame_reason(frame)))

    def _frame_reason(self, frame):
        return ('frame %r has no transform chain to the base frame %r on /tf or /tf_static (left '
                'out until one arrives)' % (frame, self.base_frame_id))

    def _follow_frames(self):
        """Subscribe /tf and /tf_static while an obstacle is in another frame, else not."""
        with self._lock:
            needed = bool(self._set.frames())
        if needed and not self._tf:
            from tf2_msgs.msg import TFMessage
            node = self._node
            self._tf = [
                node.create_subscription(TFMessage, '/tf', self._on_tf, TF_QOS,
                                         callback_group=self._group),
                node.create_subscription(TFMessage, '/tf_static', self._on_tf, TF_STATIC_QOS,
                                         callback_group=self._group)]
        elif not needed and self._tf:
            for subscription in self._tf:
                self._node.destroy_subscription(subscription)
            self._tf = []
            with self._lock:
                self._tree.clear()

    # -- diagnostics -----------------------------------------------------------------------
    def diagnose(self, level, message, values):
        """Add the obstacles' values; return (level, message): WARN naming refusals when OK."""
        with self._lock:
            current = self.current
            refusals = dict(self.refused)
            refusals.update({name: self._frame_reason(frame)
                             for name, frame in self._late().items()})
        values['obstacles'] = ', '.join(o.name for o in current) or 'none'
        if refusals:
            values['obstacles_refused'] = '; '.join(
                '%s: %s' % (name, reason) for name, reason in sorted(refusals.items()))
            if level == OK:
                return WARN, 'obstacle(s) refused: %s' % ', '.join(sorted(refusals))
        return level, message
