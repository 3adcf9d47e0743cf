"""ament_python package of the EHA SIL stack (colcon build on a ROS install, pip in the venv)."""
import importlib.util
import os
import sys

from setuptools import find_packages, setup

PACKAGE = 'eha_ros'
HERE = os.path.dirname(os.path.realpath(__file__))   # colcon --symlink-install links it
CONFIG = os.path.normpath(os.path.join(HERE, '..', '..', 'config'))   # the repository's config/


def _registry():
    """eha_ros/core/config/registry.py (standard library only), read before the install."""
    path = os.path.join(HERE, PACKAGE, 'core', 'config', 'registry.py')
    spec = importlib.util.spec_from_file_location('eha_registry', path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module        # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def _config_files() -> list:
    """data_files entries installing the repository's config/ (every file, subfolders kept) to
    share/eha_ros/config, where eha_ros.core.config.params.default_config_dir finds it through
    the ament index. Paths are relative to the folder setup.py runs in (colcon and pip run it
    in src/eha_ros; install_data refuses absolute ones); none when config/ is not beside
    (a source distribution)."""
    if not os.path.isdir(CONFIG):
        return []
    entries = []
    for folder, _, files in sorted(os.walk(CONFIG)):
        names = sorted(f for f in files if not f.startswith('.'))
        if names:
            rel = os.path.relpath(folder, CONFIG)
            target = os.path.normpath(os.path.join('share', PACKAGE, 'config', rel))
            entries.append((target, [os.path.relpath(os.path.join(folder, f)) for f in names]))
    return entries


setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE]),
        ('share/' + PACKAGE, ['package.xml']),
        ('share/' + PACKAGE + '/launch', ['launch/eha_stack.launch.py']),
    ] + _config_files(),
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
