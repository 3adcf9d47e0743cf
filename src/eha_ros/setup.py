"""ament_python package of the EHA SIL stack (colcon build on a ROS install, pip in the venv)."""
from setuptools import find_packages, setup

PACKAGE = 'eha_ros'
NODES = ['plant_sim', 'hardware_bridge', 'estimator', 'controller', 'switch_manager', 'sweep',
         'recorder', 'eha_loop', 'live']

setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE]),
        ('share/' + PACKAGE, ['package.xml']),
        ('share/' + PACKAGE + '/launch', ['launch/eha_stack.launch.py']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='EHA SIL maintainers',
    maintainer_email='maintainers@example.com',
    description='EHA software-in-the-loop stack',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [f'{n} = {PACKAGE}.nodes.{n}:main' for n in NODES],
    },
)
