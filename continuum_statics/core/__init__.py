"""Physics, no ROS: robot file, compiled kernels, IVP/BVP, cable models, estimation, tip goals."""
