"""The robot: Pinocchio kinematics and dynamics, computed-torque control, trajectory
acceptance and interpolation, the MuJoCo scene and simulation."""
