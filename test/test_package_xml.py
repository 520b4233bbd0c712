"""package.xml is what ROS tools read: it must parse with catkin_pkg (colcon's and rosdep's parser) and say
ament_python, or colcon builds a plain Python package that ``ros2 run`` cannot find."""
import os
import subprocess
import sys
import xml.dom.minidom
from pathlib import Path

import pytest
from catkin_pkg.package import parse_package

pytestmark = pytest.mark.unit

REPO_ROOT = Path(__file__).resolve().parents[1]


def test_package_xml_is_well_formed_xml():
    # minidom (expat) refuses what XML forbids, e.g. "--" inside a comment
    xml.dom.minidom.parse(str(REPO_ROOT / 'package.xml'))


def test_catkin_pkg_reads_an_ament_python_package_with_its_dependencies():
    pkg = parse_package(str(REPO_ROOT / 'package.xml'))
    pkg.validate()
    assert pkg.name == 'mwip_ros'
    assert pkg.get_build_type() == 'ament_python'
    runtime = {d.name for d in pkg.exec_depends}
    assert {'rclpy', 'sensor_msgs', 'std_msgs', 'geometry_msgs', 'std_srvs'} <= runtime


@pytest.mark.cli
def test_colcon_identifies_the_package_as_ros_ament_python():
    colcon = Path(sys.executable).parent / 'colcon'
    env = {k: v for k, v in os.environ.items() if k != 'COLCON_PREFIX_PATH'}
    proc = subprocess.run([str(colcon), 'list', '--base-paths', str(REPO_ROOT)], cwd=REPO_ROOT, env=env,
                          stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    rows = [line.split('\t') for line in proc.stdout.splitlines() if line.startswith('mwip_ros\t')]
    assert len(rows) == 1 and rows[0][-1] == '(ros.ament_python)', proc.stdout + proc.stderr
