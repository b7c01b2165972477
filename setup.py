from glob import glob

from setuptools import find_packages, setup

package_name = 'mixture_ip_ros'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml') + glob('config/*.rviz')),
        ('share/' + package_name + '/config/robots', glob('config/robots/*.yaml')),
        ('share/' + package_name + '/models', glob('models/*.urdf')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='mixture_ip_ros maintainers',
    maintainer_email='maintainers@mixture-ip-ros.invalid',
    description='Mixture of Interaction ProMPs for human-robot interaction on ROS 2 Jazzy',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'mixture-ip = mixture_ip_ros.app.cli:main',
            'sim_node = mixture_ip_ros.nodes.launch:sim_node',
            'observer_node = mixture_ip_ros.nodes.launch:observer_node',
            'estimator_node = mixture_ip_ros.nodes.launch:estimator_node',
            'bag_player = mixture_ip_ros.nodes.launch:bag_player',
        ],
    },
)
