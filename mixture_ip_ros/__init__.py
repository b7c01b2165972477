"""Mixture of Interaction ProMPs for human-robot interaction (Ewerton 2014) on ROS 2 Jazzy."""

__version__ = '0.1.0'
