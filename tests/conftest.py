"""pytest fixtures shared by the suite."""
import os
import sys

import pytest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')


@pytest.fixture(scope='session')
def rclpy_session():
    """rclpy initialised once for the test process."""
    rclpy = pytest.importorskip('rclpy')
    rclpy.init()
    yield rclpy
    rclpy.try_shutdown()


@pytest.fixture
def ros_node(rclpy_session):
    """A fresh test-side node spinning in a background thread."""
    from ros_util import Spinner
    node = rclpy_session.create_node(f'test_{os.getpid()}_{id(object())}')
    spinner = Spinner(node)
    yield node
    spinner.close()
    node.destroy_node()


@pytest.fixture(scope='module')
def params():
    """Estimator parameters as the estimator node loads them (plant.yaml + estimator.yaml)."""
    from eha_ros.core.sim.batch import node_params
    from eha_ros.core.estimator.params import SCHEMA
    return node_params('estimator', SCHEMA)
