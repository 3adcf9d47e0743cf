"""Separate-process peer for the interface test: publishes a filled sample of every eha_msgs
message on /test/<Type> at 20 Hz and serves /test/switch_channel and /test/inject_fault."""
import sys
import os

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from ros_util import MSG_TYPES, fill  # noqa: E402
import eha_msgs.msg as M  # noqa: E402
from eha_msgs.srv import InjectFault, SwitchChannel  # noqa: E402


class Peer(Node):
    def __init__(self):
        super().__init__('msg_peer')
        self.pubs = [(self.create_publisher(getattr(M, t), f'/test/{t}', 10), fill(getattr(M, t)()))
                     for t in MSG_TYPES]
        self.create_timer(0.05, self.tick)
        self.create_service(SwitchChannel, '/test/switch_channel', self.on_switch)
        self.create_service(InjectFault, '/test/inject_fault', self.on_fault)

    def tick(self):
        for pub, msg in self.pubs:
            pub.publish(msg)

    def on_switch(self, req, resp):
        resp.success = req.channel == 1
        resp.message = f'switch:{req.channel}:{req.reason}'
        return resp

    def on_fault(self, req, resp):
        resp.success = req.fault == 'msp_bias'
        resp.message = f'{req.fault}:{req.channel}:{req.magnitude!r}:{req.duration!r}'
        return resp


def main():
    rclpy.init()
    node = Peer()
    print('peer ready', flush=True)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):    # SIGINT, or SIGTERM
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
