"""The stack's tools take an identified plant (issue 43, point 5): a params file with plant.*
keys (scripts/identify's identified.yaml) reaches plant_sim alone in run_stack (composed or
not), becomes the family's centre in a campaign, and the nominal plant of design_qft; a bad
file is one line."""
import json
import os
import subprocess

import pytest

from eha_ros.core.config.cli import UsageError
from eha_ros.core.config.params import ParamError, load, override_arg, parse_ros_args
from eha_ros.core.config.registry import schema_for
from eha_ros.core.hardware.sim_params import plant_file
from eha_ros.core.sim import campaign as C
from eha_ros.core.sim import scenarios as SC
from eha_ros.tools import design_qft, run_stack
from ros_util import ROOT

IDENTIFIED = """plant_sim:
  ros__parameters:
    plant:
      friction: {F_c: 600.0, mu: 1500.0}
      drive: {Kp_w: 0.5, delay: 0.002}
"""


@pytest.fixture
def identified(tmp_path):
    path = tmp_path / 'identified.yaml'
    path.write_text(IDENTIFIED)
    return str(path)


def test_plant_file_reads_the_plant_keys_and_checks_them(tmp_path, identified):
    assert plant_file(identified) == {'plant.friction.F_c': 600.0, 'plant.friction.mu': 1500.0,
                                      'plant.drive.Kp_w': 0.5, 'plant.drive.delay': 0.002}
    wild = tmp_path / 'wild.yaml'
    wild.write_text(IDENTIFIED.replace('plant_sim:', '/**:'))
    assert plant_file(str(wild))['plant.friction.F_c'] == 600.0
    for text, words in (('plant_sim:\n  ros__parameters:\n    sim_node: {seed: 3}\n',
                         'not a plant parameter'),
                        ('plant_sim:\n  ros__parameters:\n    plant: {fluid: {betta: 1.0e9}}\n',
                         'unknown parameter'),
                        ('plant_sim:\n  ros__parameters:\n    plant: {fluid: {beta: -1.0}}\n',
                         'plant.fluid.beta = -1.0'),
                        ('estimator:\n  ros__parameters:\n    plant: {fluid: {beta: 1.0e9}}\n',
                         'sets no parameter of plant_sim')):
        bad = tmp_path / 'bad.yaml'
        bad.write_text(text)
        with pytest.raises(ParamError) as err:
            plant_file(str(bad))
        assert words in str(err.value) and '\n' not in str(err.value), err.value


def test_override_arg_reads_back_the_same_value():
    import yaml
    for v in (1e-12, 4.5e-12, 1000.0, 1e20, -3e-7, 7, True, 'stribeck', [1.0, 2e-9]):
        assert yaml.safe_load(override_arg(v)) == v


def node_values(cmd: list, node: str) -> dict:
    """What ``node`` loads from a process' command line (its --ros-args), as the node does."""
    files, overrides, _, _ = parse_ros_args(cmd[cmd.index('--ros-args'):])
    return load(schema_for(node), files, overrides, node=node)


@pytest.mark.parametrize('mode', ['realtime', 'lockstep'])
def test_run_stack_gives_the_identified_plant_to_plant_sim_alone(identified, mode):
    args = run_stack.parse(['--mode', mode, '--plant-params', identified, '-p',
                            'plant_sim:plant.friction.mu:=1600.0'])
    p = run_stack.plan(args)
    cmds = run_stack.build_stack(args, p, managed=True).commands()
    process = 'eha_loop' if mode == 'realtime' else 'plant_sim'
    sim = node_values(cmds[process], 'plant_sim')
    assert sim['plant.friction.F_c'] == 600.0 and sim['plant.drive.delay'] == 0.002
    assert sim['plant.friction.mu'] == 1600.0              # an explicit -p still wins
    for node in ('estimator', 'controller', 'switch_manager'):
        own = node_values(cmds['eha_loop' if mode == 'realtime' else node], node)
        assert own['plant.friction.F_c'] == 450.0 and own['plant.drive.delay'] == 0.001, node


@pytest.mark.parametrize('argv, words', [
    (['--plant', 'mock'], 'expected --plant sim'),
    (['--plant', 'bridge'], 'expected --plant sim'),
])
def test_run_stack_refuses_the_identified_plant_for_a_drive(identified, argv, words):
    with pytest.raises(UsageError, match=words):
        run_stack.plan(run_stack.parse(argv + ['--plant-params', identified]))


def test_campaign_centres_the_family_on_the_identified_plant(tmp_path, identified):
    """The scenario's overrides carry the file (so campaign.json and a resume keep it); the
    workers' nominal plant is the identified one, the estimator's and controller's are not;
    and a run of the same plant differs from the nominal one's."""
    scn = SC.load('step')
    scn.overrides = {**C.centre(identified), **scn.overrides}
    assert SC.from_saved(scn.as_dict()).overrides['plant_sim:plant.friction.F_c'] == 600.0
    nominal = C.nominal_params(overrides=scn.overrides)
    assert nominal['plant_sim']['plant.friction.F_c'] == 600.0
    assert nominal['plant_sim']['plant.drive.Kp_w'] == 0.5
    assert nominal['controller']['plant.friction.F_c'] == 450.0
    assert nominal['estimator']['plant.drive.Kp_w'] != 0.5
    row = {'run_id': 0, **{c: 1.0 for c in C.MULT}, 'seed': 1, 'noise_seed': 7}
    ident, _ = C.run_chunk(scn.as_dict(), nominal, [row], trace=False)
    base, _ = C.run_chunk(SC.load('step').as_dict(), C.nominal_params(), [row], trace=False)
    assert ident[0]['error'] == '' and base[0]['error'] == ''
    assert ident[0]['overshoot_pct'] != base[0]['overshoot_pct']
    with pytest.raises(UsageError, match='--plant-params: .*not a plant parameter'):
        bad = tmp_path / 'bad.yaml'
        bad.write_text('plant_sim:\n  ros__parameters:\n    sim_node: {seed: 3}\n')
        C.run_campaign('step', family={'C_eq': [1.0]}, out=str(tmp_path / 'c'),
                       plant_params=str(bad))
    assert not (tmp_path / 'c').exists()
    with pytest.raises(UsageError, match='keeps the plant it started with'):
        C.run_campaign(resume=str(tmp_path), plant_params=identified)


def test_campaign_cli_records_the_centre(tmp_path, identified):
    family = tmp_path / 'one.csv'
    family.write_text('C_eq,D_p,beta,k_T,k_E\n1,1,1,1,1\n')
    out = tmp_path / 'camp'
    res = subprocess.run([os.path.join(ROOT, 'scripts', 'campaign'), 'step', '--family',
                          str(family), '--plant-params', identified, '--workers', '1',
                          '--no-report', '--quiet', '--out', str(out)],
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    info = json.load(open(out / 'campaign.json'))
    assert info['scenario']['overrides']['plant_sim:plant.friction.F_c'] == 600.0
    assert info['rows'] == 1 and info['errors'] == 0


def test_design_qft_designs_for_the_identified_plant(identified):
    a = design_qft.parse(['--plant-params', identified])
    plant = design_qft.load_plant(a)
    assert plant['plant.friction.F_c'] == 600.0 and plant['plant.drive.Kp_w'] == 0.5
    assert design_qft.load_plant(design_qft.parse([]))['plant.drive.Kp_w'] != 0.5
    with pytest.raises(UsageError, match='--update-plant-yaml'):
        design_qft.load_plant(design_qft.parse(['--plant-params', identified,
                                                '--update-plant-yaml']))


def test_design_qft_bad_identified_file_is_one_line(tmp_path):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('plant_sim:\n  ros__parameters:\n    plant: {motor: {k_T: -1.0}}\n')
    res = subprocess.run([os.path.join(ROOT, 'scripts', 'design_qft'), '--plant-params',
                          str(bad), '--report-dir', str(tmp_path / 'r'), '--out',
                          str(tmp_path / 'c.yaml')], capture_output=True, text=True, timeout=120)
    lines = res.stderr.strip().splitlines()
    assert res.returncode == 2 and len(lines) == 1 and 'plant.motor.k_T = -1.0' in lines[0], \
        res.stderr[-1000:]
    assert not (tmp_path / 'c.yaml').exists()
