"""pytest fixtures shared by the suite."""
import gc
import os
import sys

import pytest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')


@pytest.fixture(autouse=True, scope='module')
def collected_between_modules():
    """A full collection once a module is done (its fixtures torn down), over everything
    long_lived_frozen kept out of the collector meanwhile."""
    yield
    gc.unfreeze()
    gc.collect()


@pytest.fixture(autouse=True)
def long_lived_frozen(collected_between_modules):
    """What is alive when a test starts is kept out of the collector during it (gc.freeze, as
    every node does after its start-up): in this one process a full collection over the suite's
    imports and earlier objects stalled a DDS test's commanding thread for up to 190 ms, beyond
    the plant's 50 ms command timeout. The collection before it sees only what is not frozen."""
    gc.collect()
    gc.freeze()
    yield


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
