"""ROS 2 launch file mirroring scripts/run_stack (for a ROS install with `launch`/`launch_ros`).

    ros2 launch eha_ros eha_stack.launch.py plant:=sim mode:=realtime structure:=auto \
        config_dir:=/path/to/eha/config

The processes, their executables and arguments come from eha_ros.tools.run_stack
(launch_entries), so the launch file and run_stack start the same stack; plant:=bridge swaps
only the plant side (hardware_bridge + the ADS test peer unless peer:=false). Launch has no
lifecycle manager here: the nodes reach their states by themselves (autostart parameters), a
simulated stack active, a real drive inactive unless activate:=true.
"""
import os

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, ExecuteProcess, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from eha_ros.core.config.params import default_config_dir
from eha_ros.tools.run_stack import launch_entries

ARGS = {'plant': ('sim', 'sim: plant_sim | bridge: hardware_bridge to the drive'),
        'mode': ('realtime', 'realtime | lockstep'),
        'structure': ('auto', 'auto | composed | processes (see docs/nodes/eha_loop.md)'),
        'peer': ('true', 'bridge: start the ADS test peer (false: a real PLC answers)'),
        'activate': ('false', 'bridge: activate (arm) the drive by itself once the arming '
                              'conditions hold (default: inactive until change_state activate)'),
        'sweep': ('false', 'also run the sweep node'),
        'config_dir': (os.environ.get('EHA_CONFIG_DIR', default_config_dir()),
                       'folder with the YAML files of config/')}


def processes(context):
    value = {k: LaunchConfiguration(k).perform(context) for k in ARGS}
    argv = ['--plant', value['plant'], '--mode', value['mode'], '--structure',
            value['structure'], '--config', value['config_dir']]
    if value['peer'].lower() == 'false' and value['plant'] == 'bridge':
        argv.append('--no-peer')
    if value['activate'].lower() == 'true' and value['plant'] == 'bridge':
        argv.append('--activate')
    if value['sweep'].lower() == 'true':
        argv.append('--sweep')
    actions = []
    for kind, executable, arguments in launch_entries(argv):
        if kind == 'python':
            actions.append(ExecuteProcess(cmd=['python3', '-m', executable] + arguments,
                                          output='screen'))
        else:
            actions.append(Node(package='eha_ros', executable=executable, arguments=arguments,
                                output='screen'))
    return actions


def generate_launch_description():
    return LaunchDescription(
        [DeclareLaunchArgument(k, default_value=d, description=h) for k, (d, h) in ARGS.items()]
        + [OpaqueFunction(function=processes)])
