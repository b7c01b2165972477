"""Mixture of Interaction ProMPs for human-robot interaction (Ewerton 2014) on ROS 2 Jazzy."""

import os

# Every matrix here is small (at most a few hundred rows): BLAS threads only add overhead, and
# contend with the nodes' own threads. Takes effect when this package is imported before numpy
# (the executables); a value the user set is kept.
for _name in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(_name, '1')

# numba caches the compiled kernels next to their source by default: inside an installed
# package that is a system folder (unwritable, or shared by users). The user's cache instead.
os.environ.setdefault('NUMBA_CACHE_DIR', os.path.join(
    os.environ.get('XDG_CACHE_HOME') or os.path.join(os.path.expanduser('~'), '.cache'),
    'mixture_ip_ros', 'numba'))

__version__ = '0.1.0'
