"""Parameter loader: ROS params-file format, schema checks, one-line errors with non-zero exit."""
import os
import subprocess
import sys

import pytest

from eha_ros.core.config.params import (Param, ParamError, Schema, load, parse_ros_args,
                                        read_params_file)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCHEMA = Schema('demo', [
    Param('gain.kp', 'float', 'rad/s/m', 1.0, 0.0, 100.0),
    Param('gain.ki', 'float', 'rad/s^2/m', min=0.0, max=1e4),          # required
    Param('mode', 'str', '', 'pva', choices=('pva', 'model')),
    Param('num', 'float[]', '', [1.0, 2.0]),
    Param('count', 'int', '', 3, 1, 10),
    Param('enabled', 'bool', '', True),
])


def write(tmp_path, text, name='p.yaml'):
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def test_wildcard_then_node_section_nested_keys(tmp_path):
    f = write(tmp_path, '/**:\n  ros__parameters:\n    gain: {kp: 2, ki: 3.5}\n'
                        'demo:\n  ros__parameters:\n    gain: {kp: 7.0}\n    num: [1, 2.5]\n'
                        'other:\n  ros__parameters:\n    nothing: 1\n')
    values = load(SCHEMA, [f])
    assert values['gain.kp'] == 7.0 and isinstance(values['gain.kp'], float)
    assert values['gain.ki'] == 3.5
    assert values['num'] == [1.0, 2.5]
    assert values['mode'] == 'pva' and values['count'] == 3     # defaults filled


def test_precedence_mirrors_rclpy(tmp_path):
    """Later wins within a class; named (node section, -p node:key) beats wildcard
    (/** section, plain -p) whatever the order -- what rclpy applies (rclpy PR #547)."""
    a = write(tmp_path, 'demo:\n  ros__parameters:\n    gain: {ki: 1.0, kp: 1.0}\n', 'a.yaml')
    b = write(tmp_path, 'demo:\n  ros__parameters:\n    gain: {ki: 2.0}\n'
                        '/**:\n  ros__parameters:\n    count: 4\n', 'b.yaml')
    values = load(SCHEMA, [a, b], {'gain.kp': 9, 'count': 5, 'demo:gain.ki': 7.0,
                                   'other:gain.kp': 8.0})
    assert values['gain.kp'] == 1.0            # plain -p does not beat the node's section
    assert values['gain.ki'] == 7.0            # -p demo:gain.ki:=7 does
    assert values['count'] == 5                # plain -p beats a wildcard section


def test_section_matching_like_rcl():
    from eha_ros.core.config.params import _section_class as kind
    assert kind('demo', '/demo') == 'named' and kind('demo', '/eha/demo') is None
    assert kind('/eha/demo', '/eha/demo') == 'named'
    assert kind('/**', '/eha/demo') == 'wild' and kind('/**/demo', '/demo') == 'wild'
    assert kind('/**/demo', '/eha/x/demo') == 'wild' and kind('/eha/*', '/eha/demo') == 'wild'
    assert kind('/*/demo', '/demo') is None


def test_remapped_node_name_and_namespace(tmp_path):
    f = write(tmp_path, '/eha/demo2:\n  ros__parameters:\n    gain: {ki: 4.0}\n')
    assert read_params_file(f, 'demo2', '/eha') == {'gain.ki': 4.0}
    assert read_params_file(f, 'demo', '/eha') == {}
    assert read_params_file(f, 'demo2', '/') == {}


def test_parse_ros_args():
    files, over, name, ns = parse_ros_args(
        ['--ros-args', '--params-file', 'a.yaml', '-p', 'gain.kp:=2.5', '-r', '__node:=x',
         '-r', '__ns:=/eha', '--params-file', 'b.yaml', '-p', 'mode:=model'])
    assert files == ['a.yaml', 'b.yaml']
    assert over == {'gain.kp': 2.5, 'mode': 'model'}
    assert (name, ns) == ('x', '/eha')


@pytest.mark.parametrize('text, words', [
    ('demo:\n  ros__parameters:\n    gain: {ki: 1.0, kd: 2.0}\n', ['unknown', "'gain.kd'", '2.0']),
    ('demo:\n  ros__parameters:\n    gain: {kp: 1.0}\n', ['missing', "'gain.ki'", 'float in [0, 10000]']),
    ('demo:\n  ros__parameters:\n    gain: {ki: fast}\n', ['gain.ki', "'fast'", 'expected float']),
    ('demo:\n  ros__parameters:\n    gain: {ki: -1.0}\n', ['gain.ki', '-1.0', 'in [0, 10000]']),
    ('demo:\n  ros__parameters:\n    gain: {ki: 1.0}\n    mode: kalman\n', ['mode', "'kalman'", 'pva|model']),
    ('demo:\n  ros__parameters:\n    gain: {ki: 1.0}\n    count: 2.5\n', ['count', '2.5', 'int']),
    ('demo:\n  ros__parameters:\n    gain: {ki: 1.0}\n    enabled: 1\n', ['enabled', '1', 'bool']),
    ('demo:\n  ros__parameters:\n    gain: {ki: .nan}\n', ['gain.ki', 'nan', 'float']),
    ('demo:\n  ros__parameters:\n    gain: {ki: 5e-7}\n', ['gain.ki', "'5e-7' is a string in YAML 1.1", '5.0e-7']),
    ('demo:\n  ros__parameters:\n    gain: {ki: 1.0}\n    num: [1.0, 2e3]\n', ['num', "'2e3' is a string"]),
    ('demo:\n  ros__parameters:\n    gain: {ki: [1.0}\n', ['malformed YAML', 'line 3']),
    ('demo:\n  gain: 1\n', ['section', 'ros__parameters']),
    ('- 1\n- 2\n', ['top level is list']),
])
def test_each_error_is_one_line_naming_file_key_value_expected(tmp_path, text, words):
    f = write(tmp_path, text)
    with pytest.raises(ParamError) as info:
        load(SCHEMA, [f])
    message = str(info.value)
    assert '\n' not in message
    assert f in message
    for word in words:
        assert word in message, message


def test_unreadable_file(tmp_path):
    with pytest.raises(ParamError, match=r'nope\.yaml: cannot read parameter file: no such file'):
        load(SCHEMA, [str(tmp_path / 'nope.yaml')])


# ---- the same through a real program: one line on stderr, exit code 2, no traceback ----

CHECK = [sys.executable, '-m', 'eha_ros.tools.check_config', '--node', 'plant_sim']
GOOD = os.path.join(ROOT, 'config', 'plant.yaml')


def run_check(*files):
    return subprocess.run(CHECK + list(files), capture_output=True, text=True, timeout=120)


def plant_yaml_with(old, new):
    text = open(GOOD).read()
    assert old in text, old
    return text.replace(old, new, 1)


def test_shipped_plant_config_is_valid():
    res = run_check(GOOD)
    assert res.returncode == 0, res.stderr
    assert 'ok:' in res.stdout


BAD_CASES = {
    'unknown key': (lambda: plant_yaml_with('plant:\n', 'plant:\n      pump_typo: 3.0\n'),
                    ['unknown parameter', "'plant.pump_typo'", '3.0']),
    'missing required key': (lambda: '\n'.join(l for l in open(GOOD).read().splitlines()
                                               if not l.strip().startswith('A_p:')),
                             ['missing required parameter', "'plant.cylinder.A_p'", 'm^2']),
    'wrong type': (lambda: _replace_value('D_p', '"big"'), ['plant.pump.D_p', "'big'", 'expected float']),
    'out of range': (lambda: _replace_value('D_p', '-6.684e-7'),
                     ['plant.pump.D_p', '-6.684e-07', 'expected float in [']),
    'malformed YAML': (lambda: open(GOOD).read() + '\n  : [unclosed\n', ['malformed YAML', 'line']),
}


def _replace_value(key, value):
    lines = open(GOOD).read().splitlines()
    for i, line in enumerate(lines):
        if line.strip().startswith(key + ':'):
            indent = line[:len(line) - len(line.lstrip())]
            lines[i] = f'{indent}{key}: {value}'
            return '\n'.join(lines) + '\n'
    raise AssertionError(key)


@pytest.mark.parametrize('case', sorted(BAD_CASES) + ['unreadable file'])
def test_bad_parameter_file_stops_program_with_one_line(tmp_path, case):
    if case == 'unreadable file':
        path, words = str(tmp_path / 'missing.yaml'), ['cannot read parameter file']
    else:
        make, words = BAD_CASES[case]
        path = write(tmp_path, make(), 'bad.yaml')
    res = run_check(path)
    assert res.returncode == 2, (res.returncode, res.stdout, res.stderr)
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1, res.stderr
    assert 'Traceback' not in res.stderr
    assert lines[0].startswith('check_config: error: ' + path), lines[0]
    for word in words:
        assert word in lines[0], lines[0]


CONTROLLER_FILES = [os.path.join(ROOT, 'config', f)
                    for f in ('plant.yaml', 'controller.yaml', 'controller_node.yaml')]
G = 'controller:\n  ros__parameters:\n    position_controller:\n      num: {num}\n      den: {den}\n'
NODE_AND_CHECK_CASES = {      # issue 21 item 8: what the node refuses, check_config refuses
    'not a params file': ('- 1\n- 2\n', 'top level is list'),
    'improper G': (G.format(num='[1.0, 2.0, 3.0]', den='[1.0, 2.0]'),
                   'expected a proper transfer function'),
    'G den [0, 0]': (G.format(num='[1.0]', den='[0.0, 0.0]'), 'non-zero coefficient'),
    'G of another order than its anti-windup poles': (G.format(num='[1.0]', den='[1.0, 5.0]'),
                                                      'poles for a controller of order 1'),
}


@pytest.mark.parametrize('case', sorted(NODE_AND_CHECK_CASES))
def test_check_config_and_the_node_refuse_the_same_file_with_the_same_line(tmp_path, case):
    text, words = NODE_AND_CHECK_CASES[case]
    path = write(tmp_path, text, 'bad.yaml')
    check = subprocess.run([sys.executable, '-m', 'eha_ros.tools.check_config', '--node',
                            'controller', *CONTROLLER_FILES, path],
                           capture_output=True, text=True, timeout=120)
    node = subprocess.run([os.path.join(os.path.dirname(sys.executable), 'controller'),
                           '--ros-args'] + [a for f in CONTROLLER_FILES + [path]
                                            for a in ('--params-file', f)],
                          capture_output=True, text=True, timeout=120)
    for res, prog in ((check, 'check_config'), (node, 'controller')):
        lines = res.stderr.strip().splitlines()
        assert res.returncode == 2 and len(lines) == 1, (prog, res.returncode, res.stderr)
        assert lines[0].startswith(f'{prog}: error: ') and words in lines[0], lines[0]
    assert check.stderr.split(': error: ')[1] == node.stderr.split(': error: ')[1]


def _cfg(*names):
    return [os.path.join(ROOT, 'config', n) for n in names]


# issue 19: every cross-key check lives in the schema, so the node and check_config refuse a
# file with the same line (before, check_config said "ok" for F_s < F_c, the node refused)
FRICTION = '/**:\n  ros__parameters:\n    plant:\n      friction: {F_c: 900.0, F_s: 800.0}\n'
CROSS_KEY_CASES = {
    'plant_sim F_s < F_c': ('plant_sim', _cfg('plant.yaml', 'plant_sim.yaml'), FRICTION,
                            'plant.friction.F_s = 800.0: expected >= plant.friction.F_c = 900.0'),
    'estimator F_s < F_c': ('estimator', _cfg('plant.yaml', 'estimator.yaml'), FRICTION,
                            'plant.friction.F_s = 800.0: expected >= plant.friction.F_c'),
    'controller F_s < F_c': ('controller', CONTROLLER_FILES, FRICTION,
                             'plant.friction.F_s = 800.0: expected >= plant.friction.F_c'),
    'switch_manager clear > trip': (
        'switch_manager', _cfg('plant.yaml', 'switch_manager.yaml'),
        'switch_manager:\n  ros__parameters:\n    switch:\n      health:\n'
        '        speed: {trip: 50.0, clear: 80.0}\n',
        'expected <= '),
    'sweep above Nyquist/10': ('sweep', _cfg('plant.yaml', 'sweep.yaml'),
                               'sweep:\n  ros__parameters:\n    sweep: {max_hz: 200.0}\n',
                               'above Nyquist/10'),
    'live decimation': ('live', _cfg('live.yaml'),
                        "live:\n  ros__parameters:\n    live: {decimation: ['/eha/state:0']}\n",
                        "live.decimation: '/eha/state:0'"),
}


@pytest.mark.parametrize('case', sorted(CROSS_KEY_CASES))
def test_cross_key_checks_refused_alike_by_check_config_and_the_node(tmp_path, case):
    node, files, text, words = CROSS_KEY_CASES[case]
    path = write(tmp_path, text, 'bad.yaml')
    check = subprocess.run([sys.executable, '-m', 'eha_ros.tools.check_config', '--node', node,
                            *files, path], capture_output=True, text=True, timeout=120)
    proc = subprocess.run([os.path.join(os.path.dirname(sys.executable), node), '--ros-args']
                          + [a for f in files + [path] for a in ('--params-file', f)],
                          capture_output=True, text=True, timeout=120)
    for res, prog in ((check, 'check_config'), (proc, node)):
        lines = res.stderr.strip().splitlines()
        assert res.returncode == 2 and len(lines) == 1, (prog, res.returncode, res.stderr)
        assert lines[0].startswith(f'{prog}: error: ') and words in lines[0], lines[0]
        assert 'Traceback' not in res.stderr
    assert check.stderr.split(': error: ')[1] == proc.stderr.split(': error: ')[1]
    print(check.stderr.strip())


def test_check_config_takes_overrides_with_or_without_ros_args():
    files = _cfg('plant.yaml', 'sweep.yaml')
    for extra in (['-p', 'sweep:sweep.max_hz:=200.0'],
                  ['--ros-args', '-p', 'sweep:sweep.max_hz:=200.0']):
        res = subprocess.run([sys.executable, '-m', 'eha_ros.tools.check_config', '--node',
                              'sweep', *files, *extra], capture_output=True, text=True,
                             timeout=120)
        assert res.returncode == 2 and 'above Nyquist/10' in res.stderr, res.stderr
    res = subprocess.run([sys.executable, '-m', 'eha_ros.tools.check_config', '--node', 'sweep',
                          *files, '--bogus'], capture_output=True, text=True, timeout=120)
    assert res.returncode == 2 and "unknown argument '--bogus'" in res.stderr, res.stderr


@pytest.mark.parametrize('args, words', [
    (['--params-file'], '--params-file at the end without its value'),
    (['--log-level', 'bogus'], "--log-level 'bogus': expected one of debug"),
    (['-p'], '-p at the end without its value'),
])
def test_malformed_ros_arguments_are_one_line_not_an_rcl_traceback(args, words):
    res = subprocess.run([os.path.join(os.path.dirname(sys.executable), 'controller'),
                          '--ros-args'] + [a for f in CONTROLLER_FILES
                                           for a in ('--params-file', f)] + args,
                         capture_output=True, text=True, timeout=120)
    lines = res.stderr.strip().splitlines()
    assert res.returncode == 2 and len(lines) == 1 and words in lines[0], res.stderr
