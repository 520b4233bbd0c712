from glob import glob

from setuptools import find_packages
from setuptools import setup

package_name = 'mwip_ros'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages',
            ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', sorted(glob('config/*.yaml') + glob('config/*.json'))),
        ('share/' + package_name + '/config/sweeps', sorted(glob('config/sweeps/*.yaml'))),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='mwip_ros maintainers',
    maintainer_email='maintainers@example.com',
    keywords=['ROS'],
    classifiers=[
        'Intended Audience :: Developers',
        'Programming Language :: Python',
        'Topic :: Software Development',
    ],
    description=(
        'ROS 2 control stack for a mobile wheeled inverted pendulum: '
        'DSC with a nonlinear disturbance observer (DSCNDO)'
    ),
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'plant_sim = mwip_ros.nodes.runtime.entry:plant_sim',
            'disturbance_observer = mwip_ros.nodes.runtime.entry:disturbance_observer',
            'dscndo_controller = mwip_ros.nodes.runtime.entry:dscndo_controller',
            'mcap_recorder = mwip_ros.nodes.runtime.entry:mcap_recorder',
            'bag_replay = mwip_ros.nodes.runtime.entry:bag_replay',
            'mwip_sim = mwip_ros.cli.sim:main',
            'mwip_theorem = mwip_ros.cli.theorem:main',
            'mwip_report = mwip_ros.cli.report:main',
            'mwip_bag_repair = mwip_ros.cli.bag_repair:main',
            'mwip_sweep = mwip_ros.cli.sweep:main',
            'mwip_tune = mwip_ros.cli.tune:main',
            'mwip_identify = mwip_ros.cli.identify:main',
            'mwip_robot = mwip_ros.cli.robot:main',
            'robot_markers = mwip_ros.nodes.runtime.entry:robot_markers',
            'robot_state = mwip_ros.nodes.runtime.entry:robot_state',
            'foxglove_server = mwip_ros.nodes.runtime.entry:foxglove_server',
            'mwip_ctl = mwip_ros.cli.ctl:main',
            'state_estimator = mwip_ros.nodes.runtime.entry:state_estimator',
            'mwip_moteus_emulator = mwip_ros.cli.moteus_emulator:main',
            'wheel_driver = mwip_ros.nodes.runtime.entry:wheel_driver',
        ],
    },
)
