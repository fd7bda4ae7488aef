"""The QoS of every topic of the package, stated once (doc/architecture.md, ROS interfaces)."""
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

#: Newest measurement only: best effort, keep last 1 (a slow cycle never builds a backlog).
LATEST_SENSOR_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                               reliability=ReliabilityPolicy.BEST_EFFORT,
                               durability=DurabilityPolicy.VOLATILE)
#: Latched state (backbone, tip_pose, markers): reliable, depth 1, transient local.
LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: Commands and goals: reliable, depth 10.
COMMAND_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
#: The move_tip action's goal, result and cancel services, on both sides: a burst of goals
#: queues instead of overflowing (ROS's default depth 10 lost 11 of 50 answers of a client's
#: burst even with the server keeping up; a client that sends bursts passes this too).
ACTION_SERVICE_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
#: /tf as tf2_ros's TransformBroadcaster offers it: reliable, depth 100, volatile.
TF_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                    reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
#: The ``obstacles`` input: reliable, transient local (a latched sender's last message reaches a
#: node started later), depth 10 (messages that add obstacles are not overwritten in the queue).
OBSTACLES_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                           reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: /tf_static as tf2_ros's static listener reads it: reliable, transient local, depth 100.
TF_STATIC_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                           reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.TRANSIENT_LOCAL)


def measurement_queue_qos(depth):
    """Measurements through a short queue (statics' intake): best effort, keep last ``depth``."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.VOLATILE)

