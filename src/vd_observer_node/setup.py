"""Build script of vd_observer_node (ament_python)."""

from glob import glob

from setuptools import find_packages, setup

package_name = 'vd_observer_node'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml') + glob('config/*.xml')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
    ],
    install_requires=['setuptools', 'vd_common'],
    # `vd fleet --engine dask` / `--scheduler`: the fleet replay on a Dask cluster (the local
    # process pool needs nothing more). The dev set-up installs it (requirements/python.in).
    extras_require={'fleet': ['distributed']},
    zip_safe=True,
    maintainer='vd maintainers',
    maintainer_email='maintainers@vd-project.org',
    description='Sliding-mode observers and tire force, friction and slope estimators, '
    'with MCAP bag recording and replay.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'observer_node = vd_observer_node.nodes.entry_points:observer_node',
            'estimator_node = vd_observer_node.nodes.entry_points:estimator_node',
            'alerts_node = vd_observer_node.nodes.entry_points:alerts_node',
            'recorder_node = vd_observer_node.nodes.entry_points:recorder_node',
            'player_node = vd_observer_node.nodes.entry_points:player_node',
            'pipeline_node = vd_observer_node.nodes.entry_points:pipeline_node',
            'vd = vd_observer_node.tools.cli:command',
        ],
    },
)
