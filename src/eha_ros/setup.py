"""ament_python package of the EHA SIL stack (colcon build on a ROS install, pip in the venv)."""
import importlib.util
import os
import sys

from setuptools import find_packages, setup

PACKAGE = 'eha_ros'


def _registry():
    """eha_ros/core/config/registry.py (standard library only), read before the install."""
    path = os.path.join(os.path.dirname(os.path.abspath(__file__)), PACKAGE, 'core', 'config',
                        'registry.py')
    spec = importlib.util.spec_from_file_location('eha_registry', path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module        # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


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
        'console_scripts': _registry().entry_points(),
    },
)
