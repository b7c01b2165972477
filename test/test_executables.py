"""The executables as a user runs them: a bad parameter is one line and exit code 1, and Ctrl-C
is a clean exit at any moment of a node's life."""

import os
from pathlib import Path
import signal
import subprocess
import sys

import pytest

from conftest import private_domain_id

BIN = Path(sys.executable).parent


def _env():
    return dict(os.environ, ROS_DOMAIN_ID=str(private_domain_id()))


@pytest.mark.parametrize('executable', ['observer_node', 'sim_node', 'bag_player'])
def test_a_bad_parameter_is_one_line_and_exit_1_for_every_executable(executable):
    env = dict(os.environ, ROS_DOMAIN_ID=str(private_domain_id()))
    bad = {'observer_node': 'onset_speed:=nan', 'sim_node': 'publish_rate:=-1.0',
           'bag_player': 'rate:=0.0'}[executable]
    proc = subprocess.run([str(Path(sys.executable).parent / executable), '--ros-args', '-p',
                           bad], capture_output=True, text=True, timeout=60, env=env)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 1, out
    assert 'refusing to start' in out and bad.split(':=')[0] in out, out
    assert 'Traceback' not in out, out


PROCESS_DEFAULTS = ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS',
                    'NUMBA_CACHE_DIR', 'MIXTURE_IP_CACHE', 'MUJOCO_GL')


def test_importing_the_package_changes_no_environment():
    """The package, the executables' own modules and the renderer imported in a process without
    the executables' defaults: os.environ is as it was (the environment is the executables' to
    set, when they run)."""
    code = ('import os\n'
            'before = dict(os.environ)\n'
            'import mixture_ip_ros, mixture_ip_ros.nodes.launch, mixture_ip_ros.app.cli\n'
            'import mixture_ip_ros.viz.animation, mixture_ip_ros.viz.offscreen\n'
            'changed = sorted(k for k in set(before) | set(os.environ)\n'
            '                 if before.get(k) != os.environ.get(k))\n'
            'assert not changed, changed\n')
    env = {k: v for k, v in os.environ.items() if k not in PROCESS_DEFAULTS}
    proc = subprocess.run([sys.executable, '-c', code], env=env, capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr


@pytest.mark.parametrize('command', [['mixture-ip', 'params', 'estimator_node'],
                                     ['estimator_node']])
def test_the_executables_cache_compiled_kernels_in_the_users_cache(command, tmp_path):
    """The estimator's module compiles its plan kernels when imported (the node executable
    refuses to start without a model after that); numba caches them in the user's cache folder,
    not beside the package's source."""
    env = {k: v for k, v in _env().items() if k not in PROCESS_DEFAULTS}
    env['XDG_CACHE_HOME'] = str(tmp_path)
    subprocess.run([str(BIN / command[0]), *command[1:]], env=env, capture_output=True,
                   timeout=120)
    assert list((tmp_path / 'mixture_ip_ros' / 'numba').rglob('*.nbi')), \
        'no numba cache index in the user cache'


@pytest.fixture(scope='module')
def model(tmp_path_factory):
    from mixture_ip_ros.app.training import train_to_file
    from mixture_ip_ros.scenarios.synthetic import mixture_demos
    path = tmp_path_factory.mktemp('model') / 'model.npz'
    train_to_file(mixture_demos(seed=0, n_obs=3, n_ctrl=7, n_basis=8)[0], path,
                  n_components=3, n_basis=8)
    return path


def _loaded(pid: int, library: str) -> bool:
    """Whether the process has mapped ``library`` (it is importing or has imported it)."""
    try:
        return library in Path(f'/proc/{pid}/maps').read_text()
    except OSError:
        return True       # it has exited: nothing left to wait for


def _first_line(proc) -> None:
    while proc.poll() is None and proc.stdout.read(1) not in (b'\n', b''):
        pass


@pytest.mark.parametrize('executable', ['observer_node', 'sim_node', 'estimator_node'])
def test_ctrl_c_while_starting_and_running_exits_cleanly(executable, model):
    """Ctrl-C while the node's module is being imported (rclpy's extension already loaded,
    Pinocchio, MuJoCo or numba not yet), and Ctrl-C or SIGTERM once it runs: exit code 0, no
    traceback."""
    args = {'observer_node': [], 'sim_node': ['-p', 'real_time_factor:=0.0'],
            'estimator_node': ['-p', f'model_path:={model}']}[executable]
    for moment, sig in (('importing', signal.SIGINT), ('running', signal.SIGINT),
                        ('running', signal.SIGTERM)):
        proc = subprocess.Popen([str(BIN / executable), '--ros-args', *args], env=_env(),
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
        if moment == 'importing':
            while not _loaded(proc.pid, '_rclpy_pybind11'):
                pass
        else:
            _first_line(proc)
        proc.send_signal(sig)
        try:
            out = proc.communicate(timeout=30)[0].decode(errors='replace')
        except subprocess.TimeoutExpired:
            proc.kill()
            pytest.fail(f'{executable} did not stop on Ctrl-C {moment}')
        assert proc.returncode == 0 and 'Traceback' not in out, (moment, out)


def test_ctrl_c_in_the_middle_of_start_up_takes_effect_once_it_is_complete():
    """SIGINT while the node activates (its subscriptions half made): activation completes, the
    node is not spun, it is destroyed cleanly and the exit code is 0. An interrupt raised where
    it arrived could cut rclpy's create_subscription in half and make destroy_node raise."""
    code = ('import os, signal\n'
            'from mixture_ip_ros.nodes.managed import run_node\n'
            'from mixture_ip_ros.nodes.observer_node import ObserverNode\n'
            'events = []\n'
            'class Interrupted(ObserverNode):\n'
            '    def activate(self):\n'
            '        os.kill(os.getpid(), signal.SIGINT)\n'
            '        super().activate()\n'
            "        events.append('activated')\n"
            '    def destroy_node(self):\n'
            "        events.append('destroyed')\n"
            '        return super().destroy_node()\n'
            "code = run_node(Interrupted, done=lambda node: events.append('spun'))\n"
            "print('exit', code, events)\n")
    proc = subprocess.run([sys.executable, '-c', code], env=_env(), capture_output=True,
                          text=True, timeout=120)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0 and 'Traceback' not in out, out
    assert "exit 0 ['activated', 'destroyed']" in proc.stdout, out
