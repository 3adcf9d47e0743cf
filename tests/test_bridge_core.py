"""Bridge core without ROS: symbol map validation, safety logic (arming, limits, watchdog,
link-loss latch, staleness), and the ADS link against the plant-backed test peer on loopback
(sum read/write, lock-step stepping, unknown symbol and wrong type found at the PLC)."""
import math

import pytest
import yaml

from eha_ros.core.sim.batch import node_params
from eha_ros.core.bridge.link import AdsLink, LinkError, SymbolError
from eha_ros.core.bridge.peer import AdsPeer
from eha_ros.core.hardware.gate import CommandGate
from eha_ros.core.hardware.staleness import Staleness
from eha_ros.core.bridge.symbols import ROLES, load_symbol_map
from eha_ros.core.config.params import ParamError, default_config_dir
from eha_ros.core.hardware.sim_params import SCHEMA as SIM
from ros_util import free_port

MAP = f'{default_config_dir()}/ads_symbols.yaml'


def write_map(tmp_path, edit):
    doc = yaml.safe_load(open(MAP))
    edit(doc['symbols'])
    path = tmp_path / 'map.yaml'
    path.write_text(yaml.safe_dump(doc))
    return str(path)


# ---------------------------------------------------------------- symbol map
def test_shipped_map_covers_every_role_with_si_scales():
    smap = load_symbol_map(MAP)
    assert set(smap.by_role) == set(ROLES)
    assert smap['position'].scale == 0.001 and smap['pressure_a'].scale == 1e5
    raw = smap['speed_ref'].to_plc(2 * math.pi * 1000 / 60)          # 1000 rpm
    assert raw == pytest.approx(1000.0)
    assert smap['heartbeat'].to_plc(70000) == 65535                   # clamped to UINT


@pytest.mark.parametrize('edit, words', [
    (lambda s: s.update(speed_reff=s.pop('speed_ref')), ['symbols.speed_reff', 'did you mean speed_ref']),
    (lambda s: s['speed_ref'].update(type='BOOL'), ['symbols.speed_ref.type = BOOL', 'wrong type']),
    (lambda s: s['position'].update(type='FLOAT64'), ['symbols.position.type', 'LREAL']),
    (lambda s: s.pop('heartbeat'), ['missing role', 'heartbeat']),
    (lambda s: s['position'].update(scale=0), ['symbols.position.scale = 0', 'positive']),
    (lambda s: s['position'].update(symbol='GVL.a b'), ['symbols.position.symbol']),
    (lambda s: s['pressure_b'].update(symbol=s['pressure_a']['symbol']), ['already mapped']),
])
def test_bad_map_is_one_line_naming_the_key(tmp_path, edit, words):
    with pytest.raises(ParamError) as err:
        load_symbol_map(write_map(tmp_path, edit))
    text = str(err.value)
    assert '\n' not in text and all(w in text for w in words), text


def test_malformed_or_missing_map_file(tmp_path):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('symbols: [unclosed\n')
    for path, word in ((str(bad), 'malformed YAML'), (str(tmp_path / 'none.yaml'), 'no such file')):
        with pytest.raises(ParamError, match=word):
            load_symbol_map(path)


# ---------------------------------------------------------------- safety
def make_safety(**kw):
    s = CommandGate(max_speed=kw.get('max_speed', 800.0), max_rate=kw.get('max_rate', 1e5),
                    timeout=kw.get('watchdog', 0.02), arm_max_command=10.0)
    s.set_link(True)
    s.set_data(fresh=True)
    return s


def test_unarmed_never_outputs_speed():
    s = make_safety()
    for k in range(100):
        s.set_command(500.0 * (-1) ** k, k * 1e-3)
        assert s.speed_output(k * 1e-3, 1e-3) == 0.0


def test_arm_preconditions():
    s = make_safety()
    s.set_command(300.0, 0.0)
    ok, why = s.arm()
    assert not ok and 'latest command 300.0' in why
    s.set_command(0.0, 0.0)
    s.set_data(fresh=False)
    assert 'stale' in s.arm()[1]
    s.set_data(fresh=True, drive_fault=True)
    assert 'drive reports a fault' in s.arm()[1]
    s.set_data(fresh=True)
    s.set_link(False)
    assert not s.arm()[0]
    s.set_link(True)
    assert 'reset first' in s.arm()[1]             # the loss above latched a fault
    assert 'stale' in s.reset()[1]                 # no fresh data since the link came back
    s.set_data(fresh=True)
    assert s.reset()[0] and s.arm() == (True, 'armed')


def test_armed_output_is_saturated_and_rate_limited():
    s = make_safety(max_speed=800.0, max_rate=1e5)
    assert s.arm()[0]
    out = []
    for k in range(12):
        s.set_command(5000.0, k * 1e-3)
        out.append(s.speed_output(k * 1e-3, 1e-3))
    assert out[:3] == pytest.approx([100.0, 200.0, 300.0])         # 1e5 rad/s^2 * 1 ms
    assert out[-1] == 800.0 and s.c['saturated_commands'] == 12
    assert not s.set_command(float('nan'), 0.012) and s.command == 800.0


def test_watchdog_zeroes_at_once_and_recovers_ramping():
    s = make_safety(max_rate=1e6, watchdog=0.02)
    s.arm()
    t = 0.0
    for _ in range(10):
        s.set_command(200.0, t)
        s.speed_output(t, 1e-3)
        t += 1e-3
    last_cmd = t - 1e-3
    outs = []
    while t < last_cmd + 0.03:
        outs.append((t, s.speed_output(t, 1e-3)))
        t += 1e-3
    first_zero = min(tt for tt, v in outs if v == 0.0)
    assert first_zero - last_cmd <= 0.02 + 1e-3 + 1e-9
    assert all(v == 200.0 for tt, v in outs if tt - last_cmd <= 0.02)
    assert s.c['command_timeouts'] == 1
    s.set_command(200.0, t)
    assert s.speed_output(t, 1e-3) == 200.0 and not s.stale


def test_link_loss_latches_disarms_and_needs_reset():
    s = make_safety()
    s.arm()
    s.set_link(False, 'timeout')
    assert not s.armed and s.link_fault and s.speed_output(0.0, 1e-3) == 0.0
    assert s.reset() == (False, 'reset refused: the link is still down')
    s.set_link(True)
    s.set_data(fresh=True)
    assert s.link_fault and not s.arm()[0]                # still latched after reconnect
    assert s.reset()[0] and not s.link_fault and not s.armed


def test_staleness_from_plc_cycle_counter():
    st = Staleness(0.01)
    assert not st.fresh(0.0)
    assert st.update(5, 0.0)                            # a new sample
    assert not st.update(5, 0.009) and st.fresh(0.009)  # a repeat, within the limit
    assert not st.update(5, 0.011) and not st.fresh(0.011)    # standing still too long
    assert st.update(6, 0.012) and st.fresh(0.012)


def test_each_sample_stands_for_the_plc_cycles_since_the_last():
    """seq advanced by ``ticks`` keeps the PLC's time: a late loop cycle that finds the counter
    5 on stands for 5 ticks; a repeat stands for 1, owed back by the next skipped cycle; the
    counter wraps; a counter that went back (restarted PLC) is 1 tick, counted."""
    st = Staleness(0.01, modulus=2 ** 32)
    seq, seen = 0, []
    for cycle in [10, 11, 11, 13, 14, 19, 19, 19, 20, 23, 24, 2 ** 32 - 1, 0, 1, 5, 6]:
        st.update(cycle, 0.0)
        seq += st.ticks
        seen.append((cycle, st.ticks, seq - cycle))
    assert [t for _, t, _ in seen] == [1, 1, 1, 1, 1, 5, 1, 1, 1, 1, 1, 1, 1, 1, 4, 1]
    # seq - cycle: constant while the PLC and the loop agree; a repeat puts seq one ahead
    # until a skipped cycle pays it back (the two repeats at 19 paid back at 23)
    assert [d for _, _, d in seen][:11] == [-9, -9, -8, -9, -9, -9, -8, -7, -7, -9, -9]
    assert len({d for _, _, d in seen[12:]}) == 1       # after the jump: in step again
    # 24 -> 2**32 - 1 is a jump back (modulo 2**32: more than half the range): 1 tick; the wrap
    # 2**32 - 1 -> 0 is one cycle
    assert st.jumps == 1
    st.restart()                                        # a new connection: count anew
    assert st.update(1000, 1.0) and st.ticks == 1 and st.jumps == 1


# ---------------------------------------------------------------- ADS link + peer
@pytest.fixture(scope='module')
def plant_params():
    return node_params('plant_sim', SIM)


def peer_and_link(plant_params, lockstep, sum_mode='readwrite', link_map=MAP):
    port = free_port()
    peer = AdsPeer(load_symbol_map(MAP), plant_params, port=port, lockstep=lockstep).start()
    link = AdsLink(load_symbol_map(link_map), '127.0.0.1.1.1', 851, '127.0.0.1', port, 1.0,
                   sum_mode)
    return peer, link


@pytest.mark.parametrize('sum_mode', ['readwrite', 'separate'])
def test_lockstep_peer_steps_once_per_heartbeat(plant_params, sum_mode):
    peer, link = peer_and_link(plant_params, True, sum_mode)
    try:
        block = link.connect()
        assert block['heartbeat'] == 0 and block['drive_enable_0'] and not block['drive_enable_1']
        smap = link.smap
        for hb in range(1, 301):
            block.update(heartbeat=hb, speed_ref=100.0)
            values = smap.decode_read(link.cycle(smap.encode_write(block)))
        assert values['plc_cycle'] == 300 == peer.plc.cycles
        values = smap.decode_read(link.cycle(smap.encode_write(block)))   # same heartbeat
        assert values['plc_cycle'] == 300                                    # no step
        # 100 rad/s -> 100 * D_p / A_p = 26 mm/s after the drive's spin-up
        assert values['motor_speed_0'] == pytest.approx(100.0, abs=2.0)
        assert peer.plc.plant.truth().velocity == pytest.approx(100 * 6.684e-7 / 2.572e-3,
                                                                rel=0.03)
        assert values['position'] == pytest.approx(peer.plc.plant.measure().position, abs=1e-12)
        assert link.requests == 1 + (301 if sum_mode == 'readwrite' else 602)
    finally:
        link.close()
        peer.stop()


def connect_error(plant_params, tmp_path, edit) -> str:
    """The one-line SymbolError of connecting with the symbol map changed by ``edit``."""
    path = write_map(tmp_path, edit)
    peer, link = peer_and_link(plant_params, True, link_map=path)
    try:
        with pytest.raises(SymbolError) as err:
            link.connect()
        text = str(err.value)
        assert '\n' not in text
        return text
    finally:
        link.close()
        peer.stop()


def test_unknown_symbol_found_at_connect(plant_params, tmp_path):
    text = connect_error(plant_params, tmp_path,
                         lambda s: s['pressure_b'].update(symbol='GVL_EHA.fPresure_B'))
    assert "'GVL_EHA.fPresure_B'" in text and 'unknown symbol' in text
    assert 'symbols.pressure_b.symbol' in text


def test_wrong_type_found_at_connect(plant_params, tmp_path):
    text = connect_error(plant_params, tmp_path,
                         lambda s: s['position'].update(type='REAL'))
    assert 'symbols.position.type = REAL' in text
    assert 'declares GVL_EHA.fPosition as LREAL' in text


def test_silent_plc_is_a_link_error_not_a_hang(plant_params):
    peer, link = peer_and_link(plant_params, True)
    try:
        link.timeout_ms = 50
        block = link.connect()
        peer.set_online(False)
        with pytest.raises(LinkError, match='1861'):      # ADS timeout
            link.cycle(link.smap.encode_write(block))
        peer.set_online(True)
        link.connect()                                   # a fresh route works again
        link.cycle(link.smap.encode_write(block))
    finally:
        link.close()
        peer.stop()
