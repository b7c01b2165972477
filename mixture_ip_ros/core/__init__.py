"""Core math (numpy/scipy only, no ROS): basis functions, ProMPs, Interaction ProMPs, the mixture,
phase estimation, the recursive online estimator, motion segmentation, frames."""
