"""The KUKA iiwa 14: URDF model, Pinocchio kinematics/dynamics and IK, trajectory acceptance,
computed-torque control and the MuJoCo simulation (no ROS here; nodes/sim_node.py wraps it)."""
