from glob import glob
import os

from setuptools import find_packages
from setuptools import setup

package_name = 'mech_balance'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        (os.path.join('share', package_name, 'config'),
         sorted(glob('config/*.yaml')) + sorted(glob('config/*.rviz'))),
        (os.path.join('share', package_name, 'launch'), sorted(glob('launch/*.launch.py'))),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='mech_balance maintainers',
    maintainer_email='mech_balance@example.com',
    description='Digital twin of a balanced mechanism test rig.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'mech-balance = mech_balance.cli.main:main',
            'rig_node = mech_balance.ros.node:main',
        ],
    },
)
