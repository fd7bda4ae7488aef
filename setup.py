"""ament_python build of continuum_statics (colcon on robot computers, pip -e here)."""
from glob import glob

from setuptools import find_packages, setup

package_name = 'continuum_statics'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    # The minimal CiA 402 EDS of the canopen backend (drivers/cia402_minimal.eds).
    package_data={'continuum_statics.drivers': ['*.eds']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
        ('share/' + package_name + '/config', glob('config/*.yaml') + glob('config/*.xml')
         + glob('config/*.rviz') + glob('config/*.json')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='continuum_statics maintainers',
    maintainer_email='maintainers@continuum-statics.invalid',
    description='Real-time Cosserat-rod statics and tip control for continuum robots.',
    license='Apache-2.0',
    extras_require={'test': ['pytest']},
    entry_points={
        'console_scripts': [
            'statics = continuum_statics.nodes.statics_node:main',
            'tip_controller = continuum_statics.nodes.tip_controller_node:main',
            'cable_driver = continuum_statics.nodes.cable_driver_node:main',
            'tip_load_estimator = continuum_statics.nodes.tip_load_estimator_node:main',
            'bringup = continuum_statics.nodes.bringup:main',
        ],
        # `ros2 doctor` runs the package's checks on a robot computer (doctor's findings)
        'ros2doctor.checks': ['continuum_statics = continuum_statics.tools.doctor:RobotCheck'],
        'ros2doctor.report': ['continuum_statics = continuum_statics.tools.doctor:RobotReport'],
    },
)
