"""The ROS 2 nodes (statics, tip_controller, cable_driver) and their message/parameter helpers."""
