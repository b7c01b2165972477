"""Files: rosbag2 bags, demonstration datasets, model files, interaction records."""
