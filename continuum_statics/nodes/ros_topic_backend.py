"""The topics a node lends a :class:`~continuum_statics.drivers.base.RosTopicBackend`.

The backend (ros2_control) imports no ROS: the node publishes its commands as
std_msgs/Float64MultiArray on ``command_topic`` and feeds it the JointStates of ``state_topic``.
"""
import time

from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from continuum_statics.nodes.qos import COMMAND_QOS


def lend_topics(node, current_backend):
    """Create the command publisher and the joint-state subscription; return ``send``.

    :param current_backend: callable returning the node's backend now (or None): a later
        configure hands the same topics to a new backend
    :returns: ``send(positions)``, publishing one command, for ``backend.attach_ros``
    """
    backend = current_backend()
    publisher = node.create_publisher(Float64MultiArray, backend.command_topic, COMMAND_QOS)

    def send(positions):
        publisher.publish(Float64MultiArray(data=[float(p) for p in positions]))

    def on_joint_state(msg):
        backend = current_backend()
        if backend is not None:
            backend.on_joint_state(msg.name, msg.position, msg.velocity, msg.effort,
                                   time.monotonic())

    node.create_subscription(JointState, backend.state_topic, on_joint_state,
                             qos_profile_sensor_data)
    return send
