"""Build script of vd_common (ament_python)."""

from glob import glob

from setuptools import find_packages, setup

package_name = 'vd_common'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        # the default vehicle file (clio_rl_1_1.yaml) of the simulator and the estimator
        ('share/' + package_name + '/config', glob('config/*.yaml')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='vd maintainers',
    maintainer_email='maintainers@vd-project.org',
    description='What the vd simulator and estimator share: the topic contract, the error '
    'base, the ROS 2 node plumbing, the vehicle-file parser and the Magic Formula tyre.',
    license='Apache-2.0',
    tests_require=['pytest'],
)
