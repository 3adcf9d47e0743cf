"""Sweep signals and analysis: a sweep of a known linear system recovers its analytic Bode."""
import numpy as np
import pytest
from scipy import signal

from eha_ros.core.config.cli import UsageError
from eha_ros.core.sweep.analysis import bandwidth_hz, chirp_h1, sine_point, summarize
from eha_ros.core.sweep.signals import Chirp, SteppedSine, check_sweep

TS = 1e-3
WN, ZETA = 2 * np.pi * 8.0, 0.4          # a 2nd-order "actuator" with a 8 Hz corner
SYS = signal.lti([WN ** 2], [1, 2 * ZETA * WN, WN ** 2])


def analytic(f):
    _, h = signal.freqresp(SYS, w=[2 * np.pi * f])
    return 20 * np.log10(abs(h[0])), np.degrees(np.angle(h[0]))


def test_fr_test_semantics():
    s = SteppedSine(start_hz=1, increment_hz=2, max_hz=6, periods=4, relax_s=0.5, amplitude=1e-3)
    assert [seg.freq_hz for seg in s.segments] == [1, 3, 5]       # next frequency while <= max
    seg = s.segments[1]
    assert seg.stop - seg.start == round(4 / 3 / TS)              # whole periods
    assert s.value(seg.relax_start) == 0.0 and s.value(seg.start) == 0.0
    assert s.value(seg.start + round(1 / 12 / TS)) == pytest.approx(1e-3, rel=1e-3)  # quarter period
    assert np.allclose(s.array(), [s.value(k) for k in range(s.n_ticks)])


def test_stepped_sine_recovers_analytic_bode():
    sweep = SteppedSine(start_hz=1, increment_hz=1, max_hz=15, periods=8, relax_s=0.2,
                        amplitude=1e-3)
    u = sweep.array()
    t = np.arange(len(u)) * TS
    _, y, _ = signal.lsim(SYS, u, t)
    y = y + np.random.default_rng(0).normal(0, 2e-6, len(y))      # a little sensor noise
    for seg in sweep.segments:
        p = sine_point(u[seg.start:seg.stop], y[seg.start:seg.stop], seg.freq_hz, TS)
        g, ph = analytic(seg.freq_hz)
        assert abs(p.gain_db - g) < 0.5, (seg.freq_hz, p.gain_db, g)
        assert abs(p.phase_deg - ph) < 3.0, (seg.freq_hz, p.phase_deg, ph)
        assert p.coherence > 0.99


def test_bandwidth_and_phase_at_7hz_from_points():
    freqs = np.arange(1, 16)
    pts = []
    for f in freqs:
        g, ph = analytic(f)
        from eha_ros.core.sweep.analysis import Point
        pts.append(Point(float(f), g, ph, 1.0))
    s = summarize(pts)
    w, mag, _ = signal.bode(SYS, w=2 * np.pi * np.linspace(1, 15, 20000))
    exact_bw = w[np.nonzero(mag < -3)[0][0]] / (2 * np.pi)
    assert s['bandwidth_hz'] == pytest.approx(exact_bw, rel=0.02)
    assert s['phase_at_7hz_deg'] == pytest.approx(analytic(7.0)[1], abs=1.5)
    assert bandwidth_hz([1, 2], [0.0, -1.0]) is None


def test_chirp_h1_estimate_matches_model():
    ch = Chirp(0.5, 20, 40.0, 1e-3)
    u = ch.array()
    _, y, _ = signal.lsim(SYS, u, np.arange(len(u)) * TS)
    f, h, coh = chirp_h1(u, y, TS, nperseg=8192)
    sel = (f > 1) & (f < 15)
    _, ref = signal.freqresp(SYS, w=2 * np.pi * f[sel])
    assert np.max(np.abs(20 * np.log10(np.abs(h[sel]) / np.abs(ref)))) < 0.5
    assert np.min(coh[sel]) > 0.95


@pytest.mark.parametrize('kwargs, words', [
    (dict(max_hz=60), 'above Nyquist/10'),
    (dict(amplitude=0.07), 'beyond the stroke'),
    (dict(periods=-3), 'periods -3'),
    (dict(increment_hz=0), 'increment'),
    (dict(relax_s=-1), 'relax'),
])
def test_bad_sweep_parameters_one_line(kwargs, words):
    args = dict(start_hz=1, increment_hz=1, max_hz=15, periods=8, relax_s=0.2, amplitude=1e-3,
                offset=0.0, stroke=0.12, Ts=TS)
    args.update(kwargs)
    with pytest.raises(UsageError) as info:
        check_sweep(**args)
    assert words in str(info.value) and '\n' not in str(info.value)
