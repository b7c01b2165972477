"""ROS-free online logic of the nodes: pose checks, the interaction state, held samples,
the replan schedule, the commit rule and the plans, on an injected clock."""
