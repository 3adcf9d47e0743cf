"""The ROS launch file mirrors scripts/run_stack: both take their processes from
run_stack.launch_entries / build_stack (launch itself is not installable here, so the file is
checked by its AST and the entries by value)."""
import ast
import os

from eha_ros.tools.run_stack import build_stack, launch_entries, parse, plan
from ros_util import ROOT

LAUNCH = os.path.join(ROOT, 'src', 'eha_ros', 'launch', 'eha_stack.launch.py')


def test_entries_are_the_processes_run_stack_starts():
    for argv in ([], ['--mode', 'lockstep'], ['--plant', 'bridge'],
                 ['--plant', 'bridge', '--no-peer', '--structure', 'processes']):
        args = parse(argv)
        cmds = build_stack(args, plan(args)).commands()
        entries = launch_entries(argv)
        assert len(entries) == len(cmds)
        for (kind, exe, arguments), cmd in zip(entries, cmds.values()):
            if kind == 'python':
                assert cmd[1:3] == ['-m', exe] and arguments == cmd[3:]
            else:
                assert os.path.basename(cmd[0]) == exe and arguments == cmd[1:]


def test_swap_changes_only_the_plant_side():
    sim = dict((e[1], e[2]) for e in launch_entries(['--structure', 'processes']))
    ads = dict((e[1], e[2]) for e in launch_entries(['--structure', 'processes',
                                                     '--plant', 'bridge']))
    assert set(sim) - set(ads) == {'plant_sim'}
    assert set(ads) - set(sim) == {'hardware_bridge', 'eha_ros.tools.ads_peer'}
    for name in ('estimator', 'controller', 'switch_manager'):
        assert sim[name] == ads[name]
    lock = dict((e[1], e[2]) for e in launch_entries(['--mode', 'lockstep', '--plant', 'bridge']))
    assert '--lockstep' in lock['eha_ros.tools.ads_peer']
    assert 'hardware_bridge:bridge.lockstep:=true' in lock['hardware_bridge']


def test_launch_file_uses_launch_entries_and_declares_the_options():
    tree = ast.parse(open(LAUNCH).read())
    names = {n.id for n in ast.walk(tree) if isinstance(n, ast.Name)}
    assert 'launch_entries' in names and 'generate_launch_description' in \
        {f.name for f in tree.body if isinstance(f, ast.FunctionDef)}
    keys = next(n for n in tree.body if isinstance(n, ast.Assign) and n.targets[0].id == 'ARGS')
    declared = {k.value for k in keys.value.keys}
    assert {'plant', 'mode', 'structure', 'peer', 'activate', 'sweep', 'config_dir'} <= declared
