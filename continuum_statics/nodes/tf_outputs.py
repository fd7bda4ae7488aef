"""The statics node's /tf and /tf_static publishers (frames and poses: :mod:`.tf_frames`)."""
from geometry_msgs.msg import TransformStamped
import numpy as np

from continuum_statics.nodes.pose_encoder import TransformEncoder
from continuum_statics.nodes.qos import LATCHED_QOS, TF_QOS
from continuum_statics.nodes.tf_frames import FramePoses, frames, marker_frame


def tf_outputs(node, robot, tip_frame_id='', disks=False, prefix=''):
    """Return (the /tf publisher, its encoder, the frame poses), or None without tf2_msgs.

    Publishes the tracker's marker frame on /tf_static (latched) at once when the robot file
    sets ``tip_marker``.
    """
    try:
        from tf2_msgs.msg import TFMessage
    except ImportError:
        node.get_logger().warning('tf2_msgs is not installed: no /tf (make venv builds it; '
                                  'on a robot computer rosdep installs it)')
        return None
    names, arc_lengths = frames(robot, tip_frame_id, disks, prefix)
    marker = np.asarray(robot.tip_marker, dtype=float)
    if marker.any():  # the tracker's marker: fixed on the tip frame, /tf_static (latched)
        static = TransformStamped(child_frame_id=marker_frame(names[0]))
        static.header.frame_id = names[0]
        static.header.stamp = node.get_clock().now().to_msg()
        t = static.transform.translation
        t.x, t.y, t.z = (float(v) for v in marker)
        static.transform.rotation.w = 1.0
        node.tf_static = node.create_publisher(TFMessage, '/tf_static', LATCHED_QOS)
        node.tf_static.publish(TFMessage(transforms=[static]))
    return (node.create_publisher(TFMessage, '/tf', TF_QOS),
            TransformEncoder(robot.base_frame_id, names), FramePoses(arc_lengths))


def republish_tf(tf, shape, now_ns, reject):
    """Publish the frames of ``shape`` again on /tf (``tf``: :func:`tf_outputs`'s), stamped now.

    A passive rod's, for listeners started later; ``reject(kind, reason)`` when not finite.
    """
    publisher, encoder, poses = tf
    sec, nanosec = divmod(now_ns, 1_000_000_000)
    try:
        publisher.publish(encoder.encode(sec, nanosec, *poses.of(shape)))
    except ValueError as error:
        reject('shape', error)
