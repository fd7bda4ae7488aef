"""What the nodes decide, without ROS: the tip-goal run and the shape tracking per measurement.

The nodes parse messages into the records of :mod:`records`, call these objects and publish what
they return, so the decisions are tested without DDS (``test/test_control_*.py``).
"""
