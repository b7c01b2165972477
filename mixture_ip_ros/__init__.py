"""Mixture of Interaction ProMPs for human-robot interaction (Ewerton 2014) on ROS 2 Jazzy."""

import os

# Every matrix here is small (at most a few hundred rows): BLAS threads only add overhead, and
# contend with the nodes' own threads. Takes effect when this package is imported before numpy
# (the executables); a value the user set is kept.
for _name in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(_name, '1')

__version__ = '0.1.0'
