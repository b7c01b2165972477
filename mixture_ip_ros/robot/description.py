"""The robot's description: names of its joints and frames and its model file (no heavy imports:
io and nodes read the names without loading Pinocchio or MuJoCo)."""

# The KUKA LBR iiwa 14 R820 (models/iiwa14.urdf).
JOINT_NAMES = tuple(f'iiwa_joint_{i}' for i in range(1, 8))
BASE_FRAME = 'iiwa_link_0'
FLANGE_FRAME = 'tool0'
URDF_NAME = 'iiwa14.urdf'
