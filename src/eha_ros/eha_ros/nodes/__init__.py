"""ROS 2 nodes: thin rclpy wrappers around the core objects (one module per executable)."""
import os as _os
import signal as _signal
import sys as _sys

# Started as a node executable: Ctrl-C / SIGTERM while the (slow) imports still run ends the
# process quietly with 130 / 143, not with a KeyboardInterrupt traceback. common.spin
# installs the real handlers once the node exists.
from ..core.config.registry import NODES as _NODES   # standard library only: cheap

if _os.path.basename(_sys.argv[0] if _sys.argv else '') in _NODES:
    for _sig, _code in ((_signal.SIGINT, 130), (_signal.SIGTERM, 143)):
        _signal.signal(_sig, lambda *_, code=_code: _sys.exit(code))
