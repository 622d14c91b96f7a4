"""Build script of vd_sim_node (ament_python)."""

from glob import glob

from setuptools import find_packages, setup

package_name = 'vd_sim_node'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
        ('share/' + package_name + '/config/scenarios', glob('config/scenarios/*.yaml')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
    ],
    install_requires=['setuptools', 'vd_common'],
    zip_safe=True,
    maintainer='vd maintainers',
    maintainer_email='maintainers@vd-project.org',
    description='Bond-graph Renault Clio RL 1.1 simulator publishing wheel angles, speed, '
    'torques and ground truth.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'sim_node = vd_sim_node.entry:sim_node',
        ],
    },
)
