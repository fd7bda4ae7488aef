"""statics' obstacles: the ``obstacles`` topic, the set its solves use, ``contacts`` out.

- :class:`~continuum_statics.nodes.obstacle_topic.ObstacleTopic` keeps the robot file's
  obstacles merged with the topic's in the base frame; every change goes to the shape tracker
  (``ShapeTracker.obstacles``), so the next estimate rests the body on them.
- ``contacts`` (continuum_statics_interfaces/msg/Contacts, latched like ``backbone``) with every
  published shape: its stamp, the base frame, one entry per contact of the shape (obstacle name,
  arc length s, point, normal from the obstacle towards the body, force N), empty arrays when
  nothing touches. The empty message is bytes filled from a template (the 1 kHz path).
- On /diagnostics: ``obstacles`` (names), ``obstacles_refused`` (by name, why), ``contacts``
  (obstacle@s of each) and ``contact_force_max_n``.
"""
from continuum_statics.nodes.obstacle_messages import EmptyContacts, contacts_msg
from continuum_statics.nodes.obstacle_topic import ObstacleTopic
from continuum_statics.nodes.qos import LATCHED_QOS


def load_contacts_type():
    """Return the Contacts message type, or None when the interfaces package is not built."""
    try:
        from continuum_statics_interfaces.msg import Contacts
    except ImportError:
        return None
    return Contacts


class StaticsObstacles:
    """The obstacles of a statics node and its ``contacts`` output.

    :param node: the statics node (``robot``, ``base_frame_id``)
    :param tracker: its :class:`~continuum_statics.control.shape_tracking.ShapeTracker`
    :param on_change: called (no arguments) after the tracker got a new obstacle set, or None
    """

    def __init__(self, node, tracker, on_change=None):
        self._tracker = tracker
        self._on_change = on_change
        self.frame_id = node.base_frame_id
        self.latest = ()  # contacts of the newest published shape
        self.topic = ObstacleTopic(node, node.robot, self._changed)
        msg_type = load_contacts_type()
        self._pub = None if msg_type is None else node.create_publisher(
            msg_type, 'contacts', LATCHED_QOS)
        self._empty = None if msg_type is None else EmptyContacts(self.frame_id)

    @property
    def version(self):
        """Counts the changes of the obstacle set."""
        return self.topic.version

    def _changed(self, obstacles):
        self._tracker.obstacles = obstacles
        if self._on_change is not None:
            self._on_change()

    def published(self, shape, sec, nanosec, reject):
        """Publish the contacts of a shape just published (its stamp); ``reject(kind, why)``."""
        contacts = tuple(getattr(shape, 'contacts', ()))
        self.latest = contacts
        if self._pub is None:
            return
        if not contacts:
            self._pub.publish(self._empty.encode(sec, nanosec))
            return
        try:
            msg = contacts_msg(contacts, self.frame_id, sec, nanosec)
        except ValueError as error:
            reject('contacts', error)
            return
        self._pub.publish(msg)

    def diagnose(self, level, message, values):
        """Add the obstacles' and contacts' values; return (level, message)."""
        level, message = self.topic.diagnose(level, message, values)
        contacts = self.latest
        values['contacts'] = ', '.join('%s@%.4f' % (c.obstacle, c.s) for c in contacts) \
            or 'none'
        values['contact_force_max_n'] = max((float(c.force) for c in contacts), default=0.0)
        return level, message
