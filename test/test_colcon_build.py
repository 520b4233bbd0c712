"""The package builds with `colcon build` into a working ament_python layout."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.e2e

REPO_ROOT = Path(__file__).resolve().parents[1]
PACKAGE = 'mwip_ros'
CONSOLE_SCRIPTS = [
    'plant_sim',
    'disturbance_observer',
    'dscndo_controller',
    'mcap_recorder',
    'bag_replay',
    'mwip_sim',
    'mwip_theorem',
    'mwip_report',
    'mwip_bag_repair',
    'mwip_sweep',
    'mwip_tune',
    'robot_markers',
    'foxglove_server',
    'mwip_ctl',
    'state_estimator',
]
PACKAGE_FILES = ['package.xml', 'setup.py', 'setup.cfg']
PACKAGE_DIRS = ['resource', PACKAGE, 'config']
IGNORE = shutil.ignore_patterns('__pycache__', '*.pyc', '*.egg-info')


def _copy_package(dest: Path) -> None:
    dest.mkdir(parents=True)
    for name in PACKAGE_FILES:
        shutil.copy2(REPO_ROOT / name, dest / name)
    for name in PACKAGE_DIRS:
        src = REPO_ROOT / name
        if src.is_dir():
            shutil.copytree(src, dest / name, ignore=IGNORE)
    # config/paper.yaml may not be written yet; only ever patch the copy.
    paper = dest / 'config' / 'paper.yaml'
    if not paper.exists():
        paper.parent.mkdir(exist_ok=True)
        paper.write_text('placeholder: true  # created by test_colcon_build\n')


def _colcon() -> Path:
    colcon = Path(sys.executable).parent / 'colcon'
    if not colcon.is_file():
        pytest.fail(
            f'colcon not found at {colcon}; install colcon-common-extensions '
            'into the venv (scripts/setup.sh does this)')
    return colcon


def test_colcon_build_installs_ament_python_layout(tmp_path):
    colcon = _colcon()
    ws = tmp_path / 'ws'
    _copy_package(ws / 'src' / PACKAGE)

    env = dict(os.environ)
    env['AMENT_PREFIX_PATH'] = sys.prefix
    env['COLCON_HOME'] = str(tmp_path / 'colcon_home')
    env.pop('COLCON_PREFIX_PATH', None)
    proc = subprocess.run(
        [str(colcon), 'build', '--base-paths', 'src'],
        cwd=ws, env=env, stdin=subprocess.DEVNULL,
        capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, (
        f'colcon build failed (exit {proc.returncode})\n'
        f'--- stdout ---\n{proc.stdout}\n--- stderr ---\n{proc.stderr}')

    prefix = ws / 'install' / PACKAGE
    lib_dir = prefix / 'lib' / PACKAGE
    for name in CONSOLE_SCRIPTS:
        script = lib_dir / name
        assert script.is_file(), f'missing console script {script}'
        assert os.access(script, os.X_OK), f'not executable: {script}'

    share = prefix / 'share' / PACKAGE
    assert (share / 'package.xml').is_file()
    assert (share / 'config' / 'paper.yaml').is_file()
    assert (share / 'config' / 'sweeps' / 'mass_mismatch.yaml').is_file()

    # Ask the built workspace for the package as ROS does: source install/setup.bash in an environment
    # that knows no prefix, then look the package up in the ament index (ros2 pkg executables and
    # ros2 run list prefix/lib/<package>/ through ament_index_python.get_package_prefix).
    assert (share / 'hook' / 'ament_prefix_path.dsv').is_file(), (
        'no ament_prefix_path hook: colcon did not build the package as ros.ament_python')
    child_env = {k: v for k, v in os.environ.items()
                 if k not in ('AMENT_PREFIX_PATH', 'COLCON_PREFIX_PATH', 'PYTHONPATH', 'CMAKE_PREFIX_PATH')}
    lookup = (
        'import json, os\n'
        'from ament_index_python.packages import get_package_prefix, get_package_share_directory\n'
        f'prefix = get_package_prefix({PACKAGE!r})\n'
        f'lib = os.path.join(prefix, "lib", {PACKAGE!r})\n'
        'exes = sorted(f for f in os.listdir(lib)\n'
        '              if os.path.isfile(os.path.join(lib, f)) and os.access(os.path.join(lib, f), os.X_OK))\n'
        f'print(json.dumps({{"prefix": prefix, "share": get_package_share_directory({PACKAGE!r}), '
        '"executables": exes}))\n')
    found = subprocess.run(
        ['bash', '-c', f'source {ws / "install" / "setup.bash"} && exec "{sys.executable}" -c "$0"', lookup],
        env=child_env, stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=60)
    assert found.returncode == 0, found.stderr
    index = json.loads(found.stdout.strip().splitlines()[-1])
    assert os.path.realpath(index['prefix']) == os.path.realpath(prefix)
    assert os.path.realpath(index['share']) == os.path.realpath(share)
    assert set(CONSOLE_SCRIPTS) <= set(index['executables']), index['executables']
    # what `ros2 run mwip_ros mwip_theorem ...` would start: the executable the index names, from the install
    ran = subprocess.run(
        ['bash', '-c', f'source {ws / "install" / "setup.bash"} && exec "$0" --params "$1"',
         os.path.join(index['prefix'], 'lib', PACKAGE, 'mwip_theorem'), str(share / 'config' / 'paper.yaml')],
        env=child_env, stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=120)
    assert ran.returncode == 0, ran.stdout + ran.stderr
    assert 'gamma' in ran.stdout, ran.stdout
