"""A stray publisher for bench/faults.py and test/test_faults.py: a node that is not the sim's
commander (``stray_commander``) publishing JointTrajectory on the arm's command topic, in a
process of its own, with the liveliness lease the estimator offers (so the sim matches it).

It prints ``ready`` once its node exists, then is driven by lines on stdin: ``go N`` creates
its publisher and prints ``matched`` once N subscriptions have matched it; ``send N``
publishes N trajectories 0.1 s apart (header.frame_id 'stray', to a posture 0.3 rad from the
arm's home on every joint, in 1 s, starting now) and prints ``sent N``; ``quit`` (or the end
of stdin) destroys the publisher and exits. Its publisher appears only on ``go``: a stray
there from the start would have every command of the interaction refused.

    python bench/_fault_stray.py     (ROS_DOMAIN_ID from the environment)
"""

import sys
import time

import rclpy
from builtin_interfaces.msg import Duration
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from mixture_ip_ros.nodes import qos
from mixture_ip_ros.robot.description import DEFAULT, JOINT_NAMES

NAME = 'stray_commander'
LEASE = 0.1     # s, as the estimator's liveliness_lease


def stray_command() -> JointTrajectory:
    goal = DEFAULT.home_array() + 0.3
    point = JointTrajectoryPoint(positions=goal.tolist(), velocities=[0.0] * len(goal),
                                 time_from_start=Duration(sec=1))
    msg = JointTrajectory(joint_names=list(JOINT_NAMES), points=[point])
    msg.header.frame_id = 'stray'
    return msg


def main() -> int:
    rclpy.init()
    node = rclpy.create_node(NAME, enable_rosout=False)
    pub = None
    print('ready', flush=True)
    try:
        for line in sys.stdin:
            word, _, arg = line.strip().partition(' ')
            if word == 'go':
                pub = node.create_publisher(JointTrajectory, 'joint_trajectory',
                                            qos.command(10, LEASE))
                while pub.get_subscription_count() < int(arg or 1):
                    time.sleep(0.01)
                print('matched', flush=True)
            elif word == 'send':
                for _ in range(int(arg)):
                    pub.publish(stray_command())
                    time.sleep(0.1)
                print(f'sent {int(arg)}', flush=True)
            elif word == 'quit':
                break
        if pub is not None:
            node.destroy_publisher(pub)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
