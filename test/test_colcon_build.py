"""The package builds with `colcon build` into a working ament_python layout; and the ROS user's path: a Python
environment holding only what package.xml declares, the workspace built with colcon under it, every executable
and DSCNDO's lockstep graph run from install/."""

import ast
import csv
import importlib
import json
import math
import os
import re
import shutil
import subprocess
import sys
import time
from importlib import metadata
from pathlib import Path

import pytest
from catkin_pkg.package import parse_package

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
    'mwip_identify',
    'mwip_moteus_emulator',
    'robot_markers',
    'foxglove_server',
    'mwip_ctl',
    'state_estimator',
    'robot_state',
    'mwip_robot',
    'wheel_driver',
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


# --- the ROS user's path ----------------------------------------------------------------------------------------

# package.xml's exec_depend keys -> the pip package that provides each (ROS: the PyPI wheels requirements.txt
# pins; rosdep keys: the PyPI package behind the key, rosdep/mwip_ros.yaml for the -pip ones).  A key missing
# here fails the test: map it.
KEY_TO_PIP = {
    'rclpy': 'ros-jazzy-rclpy[fastrtps]', 'rcl_interfaces': 'ros-jazzy-rclpy[fastrtps]',
    'builtin_interfaces': 'ros-jazzy-rclpy[fastrtps]',
    'sensor_msgs': 'ros-jazzy-common-interfaces', 'std_msgs': 'ros-jazzy-common-interfaces',
    'geometry_msgs': 'ros-jazzy-common-interfaces', 'visualization_msgs': 'ros-jazzy-common-interfaces',
    'diagnostic_msgs': 'ros-jazzy-common-interfaces',
    'std_srvs': 'ros-jazzy-std-srvs', 'rosgraph_msgs': 'ros-jazzy-rosgraph-msgs',
    'ament_index_python': 'ros-jazzy-ament-index-python',
    'python3-numpy': 'numpy', 'python3-scipy': 'scipy', 'python3-matplotlib': 'matplotlib',
    'python3-yaml': 'PyYAML', 'python3-tqdm': 'tqdm', 'python3-pil': 'pillow', 'python3-numba': 'numba',
    'python3-llvmlite-pip': 'llvmlite', 'python3-daqp-pip': 'daqp', 'python3-mcap-pip': 'mcap',
    'python3-mcap-ros2-support-pip': 'mcap-ros2-support', 'python3-zstandard-pip': 'zstandard',
    'python3-lz4-pip': 'lz4', 'python3-foxglove-sdk-pip': 'foxglove-sdk', 'python3-dask-pip': 'dask[distributed]',
    'python3-distributed-pip': 'distributed', 'python3-mujoco-pip': 'mujoco', 'python3-gymnasium-pip': 'gymnasium',
    'python3-moteus-pip': 'moteus', 'python3-upkie-pip': 'upkie', 'python3-upkie-description-pip': 'upkie-description',
    'python3-pybullet-pip': 'pybullet', 'urdfdom_py': 'urdf_parser_py',
    'nav_msgs': 'ros-jazzy-common-interfaces',
    'tf2_msgs': None,   # no PyPI wheel: robot_state's /tf only where a full ROS install has it (optional)
}
# what the ROS user's colcon builds with (buildtool, not in package.xml): handed to the build only, on PYTHONPATH
BUILD_TOOLS = ('colcon_core', 'setuptools')


def _norm(name: str) -> str:
    return re.sub(r'[-_.]+', '-', name.split('[')[0]).lower()


def _declared_pip_requirements():
    """The pinned pip requirements of package.xml's exec_depends: requirements.txt's line for a package it pins,
    else the version this venv has (a package that only comes with another, e.g. lz4 with mcap)."""
    pkg = parse_package(str(REPO_ROOT / 'package.xml'))
    keys = sorted({d.name for d in pkg.exec_depends} | {d.name for d in pkg.run_depends})
    unmapped = [k for k in keys if k not in KEY_TO_PIP]
    assert not unmapped, f'package.xml declares {unmapped}: add each to KEY_TO_PIP (its pip package)'
    pins = {}
    for line in (REPO_ROOT / 'requirements.txt').read_text().splitlines():
        line = line.split('#', 1)[0].strip()
        if line:
            pins[_norm(re.split(r'[=<>!~ ]', line, maxsplit=1)[0])] = line
    wanted = []
    for name in dict.fromkeys(KEY_TO_PIP[k] for k in keys if KEY_TO_PIP[k]):
        if _norm(name) in pins:
            line = pins[_norm(name)]
            wanted.append(name + line[len(line.split('=')[0].rstrip('<>!~')):] if '[' in name and '[' not in line
                          else line)
        else:
            wanted.append(f'{name}=={metadata.version(name.split("[")[0])}')
    return wanted


def _third_party_imports():
    """Every top-level third-party module mwip_ros imports (read from its sources: the import statements, and the
    optional packages mwip_ros/optional.py names)."""
    optional = ast.parse((REPO_ROOT / PACKAGE / 'optional.py').read_text())
    table = next(n.value for n in ast.walk(optional) if isinstance(n, ast.AnnAssign) and n.target.id == 'OPTIONAL')
    found = {k.value for k in table.keys}
    for f in (REPO_ROOT / PACKAGE).rglob('*.py'):
        for n in ast.walk(ast.parse(f.read_text())):
            mods = ([a.name for a in n.names] if isinstance(n, ast.Import) else
                    [n.module] if isinstance(n, ast.ImportFrom) and n.module and not n.level else [])
            found |= {m.split('.')[0] for m in mods}
    return sorted(m for m in found if m not in sys.stdlib_module_names and m != PACKAGE and not m.startswith('_'))


def _sourced_env(ws: Path, base: dict) -> dict:
    """``base`` after ``source install/setup.bash``, as a shell a user opens has it."""
    out = subprocess.run(['bash', '-c', f'source {ws / "install" / "setup.bash"} && env -0'], env=base,
                         stdin=subprocess.DEVNULL, capture_output=True, timeout=60)
    assert out.returncode == 0, out.stderr.decode()
    return dict(item.split('=', 1) for item in out.stdout.decode().split('\0') if '=' in item)


def test_a_ros_user_builds_and_runs_the_graph_with_only_the_declared_dependencies(tmp_path):
    """A venv of only package.xml's dependencies (pinned, from PyPI: the ROS wheels and the rosdep keys' packages),
    the workspace built by colcon under that Python, then from install/, in an environment that knows nothing
    of the project's .venv: every third-party module mwip_ros imports is importable (an undeclared one is not
    installed), every executable answers --help, and DSCNDO's lockstep graph runs 2 s upright."""
    from graphproc import Graph
    started = {'start': time.monotonic()}
    fresh = tmp_path / 'fresh'
    subprocess.run([sys._base_executable, '-m', 'venv', '--without-pip', str(fresh)], check=True, timeout=120)
    python = fresh / 'bin' / 'python'
    wanted = _declared_pip_requirements()
    pip = subprocess.run([sys.executable, '-m', 'pip', '--python', str(python), 'install', '-q',
                          '--disable-pip-version-check', *wanted], capture_output=True, text=True, timeout=900)
    assert pip.returncode == 0, pip.stdout + pip.stderr
    started['venv'] = time.monotonic()
    ws = tmp_path / 'ws'
    _copy_package(ws / 'src' / PACKAGE)

    # a clean environment: no project venv, no PYTHONPATH; the ROS prefix is the fresh venv (its ROS wheels)
    clean = {k: os.environ[k] for k in ('HOME', 'LANG', 'TMPDIR', 'USER') if k in os.environ}
    clean.update(PATH='/usr/bin:/bin', AMENT_PREFIX_PATH=str(fresh), MPLBACKEND='Agg')
    tools = sorted({str(Path(importlib.import_module(t).__file__).parents[1]) for t in BUILD_TOOLS})
    build_env = dict(clean, PYTHONPATH=os.pathsep.join(tools), COLCON_HOME=str(tmp_path / 'colcon_home'))
    built = subprocess.run([str(python), '-c', 'import sys; from colcon_core.command import main; sys.exit(main())',
                            'build', '--base-paths', 'src'], cwd=ws, env=build_env, stdin=subprocess.DEVNULL,
                           capture_output=True, text=True, timeout=300)
    assert built.returncode == 0, built.stdout + built.stderr

    started['build'] = time.monotonic()
    env = _sourced_env(ws, clean)
    lib = ws / 'install' / PACKAGE / 'lib' / PACKAGE
    where = subprocess.run([str(python), '-c', 'import importlib, sys, mwip_ros\n'
                            'print(mwip_ros.__file__); print(sys.prefix)\n'
                            'for m in sys.argv[1:]:\n'
                            '    try:\n        importlib.import_module(m)\n'
                            '    except ImportError as e:\n        print("missing", m, e)\n',
                            *_third_party_imports()], env=env, cwd=tmp_path, capture_output=True, text=True,
                           timeout=120)
    assert where.returncode == 0, where.stderr
    lines = where.stdout.splitlines()
    assert lines[0].startswith(str(ws / 'install')) and lines[1] == str(fresh), lines[:2]
    assert not [line for line in lines[2:] if line.startswith('missing')], (
        'imported by mwip_ros but not installed from package.xml\'s declarations: ' + '; '.join(lines[2:]))

    for name in CONSOLE_SCRIPTS:
        script = lib / name
        assert script.read_text().splitlines()[0] == f'#!{python}', (name, script.read_text()[:200])
        helped = subprocess.run([str(script), '--help'], env=env, cwd=tmp_path, stdin=subprocess.DEVNULL,
                                capture_output=True, text=True, timeout=120)
        assert helped.returncode == 0 and 'usage' in helped.stdout.lower(), (name, helped.stdout + helped.stderr)

    started['help'] = time.monotonic()
    share = ws / 'install' / PACKAGE / 'share' / PACKAGE / 'config' / 'paper.yaml'
    csv_path = tmp_path / 'graph.csv'
    with Graph(tmp_path) as g:
        g.env = dict(env, ROS_DOMAIN_ID=g.env['ROS_DOMAIN_ID'], ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
                     PYTHONUNBUFFERED='1')
        for node, extra in (('disturbance_observer', ()), ('dscndo_controller', ('-p', 'law:=dsc', '-p',
                                                                                 'use_observer:=true'))):
            g.start(node, '-p', 'use_sim_time:=true', *extra, params=share, cmd=[str(lib / node)])
        plant = g.start('plant_sim', '-p', f'csv:={csv_path}', '-p', 'duration_s:=2.0', params=share,
                        cmd=[str(lib / 'plant_sim')])
        code = plant.wait(180)
    assert code == 0, plant.output()
    with open(csv_path) as f:
        rows = list(csv.DictReader(f))
    theta_b = [float(r['theta_b']) for r in rows]
    assert len(rows) == 401 and all(math.isfinite(t) for t in theta_b), (len(rows), plant.output())
    assert max(abs(t) for t in theta_b) < 0.5 and abs(theta_b[-1]) < 0.1, (max(map(abs, theta_b)), theta_b[-1])
    started['graph'] = time.monotonic()
    phases = list(started.items())
    print('\nthe ROS user\'s path: ' + ', '.join(f'{name} {t - phases[i - 1][1]:.0f} s' for i, (name, t)
                                                   in enumerate(phases) if i)
          + f' ({len(wanted)} pinned requirements, {len(CONSOLE_SCRIPTS)} executables; 2 s of DSCNDO lockstep, '
          f'max |theta_b| {max(abs(t) for t in theta_b):.4f} rad)')
