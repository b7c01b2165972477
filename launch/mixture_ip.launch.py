"""The nodes of `mixture-ip run` for a full ROS 2 install:

    ros2 launch mixture_ip_ros mixture_ip.launch.py model_path:=model.npz bag:=BAG_FOLDER

A bag is replayed on the sim's clock, as `mixture-ip run --bag` does; with bag:='' (the
default) no player starts and the wrist comes from live mocap on /mocap/wrist. The same
executables, params files and parameters as app/bringup.py (test/test_bringup.py checks it)."""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration, PythonExpression
from launch_ros.actions import Node

PACKAGE = 'mixture_ip_ros'


def _params_file(name):
    return os.path.join(get_package_share_directory(PACKAGE), 'config', name)


def generate_launch_description():
    model_path = LaunchConfiguration('model_path')
    robot = LaunchConfiguration('robot')
    bag = LaunchConfiguration('bag')
    # A replayed bag runs on the sim's clock, live mocap (stamped on the wall clock) on the
    # wall clock, the sim's too.
    replay = PythonExpression(["'", bag, "' != ''"])
    return LaunchDescription([
        DeclareLaunchArgument('model_path', description='trained model file (.npz)'),
        DeclareLaunchArgument('robot', default_value='iiwa14',
                              description='a shipped robot name or a description file'),
        DeclareLaunchArgument('bag', default_value='',
                              description="rosbag2 folder to replay ('' = live mocap)"),
        Node(package=PACKAGE, executable='sim_node', output='screen',
             parameters=[_params_file('sim.yaml'),
                         {'robot': robot, 'simulated_time': replay}]),
        Node(package=PACKAGE, executable='observer_node', output='screen',
             parameters=[_params_file('observer.yaml'),
                         {'use_sim_time': replay, 'robot': robot}]),
        Node(package=PACKAGE, executable='estimator_node', output='screen',
             parameters=[_params_file('estimator.yaml'),
                         {'use_sim_time': replay, 'model_path': model_path, 'robot': robot}]),
        Node(package=PACKAGE, executable='bag_player', output='screen',
             condition=IfCondition(replay),
             parameters=[_params_file('bag_player.yaml'),
                         {'use_sim_time': True, 'rewrite_stamps': True,
                          'topics': ['/mocap/wrist'], 'start_delay': 2.0,
                          'wait_for_subscribers': 1, 'bag': bag}]),
    ])
