"""Steady-state physics: speed ratio D_p/A_p (eq. 4.44 gain) and the 23 kN hold (Fig. 4.47)."""
import numpy as np

from eha_ros.core.sim.pid_loop import make_plant, plant_loop as closed_loop


def test_piston_over_motor_speed_is_Dp_over_Ap():
    """Mean piston speed from the displacement over 0.1 s (the Stribeck friction can keep the
    ~760 Hz hydraulic mode in a limit cycle, which 1 kHz samples of v would alias)."""
    plant = make_plant({'plant.sensors.noise': False})
    plant.reset(position=-0.05)
    w = []
    for k in range(250):
        plant.step(400.0)
        if k == 149:
            x0 = plant.truth().position
        if k >= 150:
            w.append(plant.truth().motor_speed[0])
    ideal = plant.p.D_p / plant.p.A_p
    ratio = (plant.truth().position - x0) / (0.1 * float(np.mean(w)))
    print(f'v/omega = {ratio:.4e}, D_p/A_p = {ideal:.4e} ({(ratio / ideal - 1) * 100:+.2f} %)')
    assert abs(ratio / ideal - 1) < 0.02
    assert ratio < ideal                     # leakage can only lose flow
    assert abs(plant.truth().position) < 0.05


def test_23kN_load_held_at_fixed_position():
    plant = make_plant({'plant.sensors.noise': False})
    load = 23e3
    # the Table 3.8 PID has an integral time Kp/Ki = 8.5 s: give it time to remove the
    # ~0.8 mm proportional error needed to turn the motor against the leakage
    run = closed_loop(plant, 30.0, lambda t: 0.0, lambda t: load if t >= 0.2 else 0.0)
    last = run['t'] > 29.0
    x = run['x'][last]
    dp = (run['p_a'] - run['p_b'])[last]
    relief = plant.p.relief_crack + plant.truth().pressure_acc
    print(f'23 kN hold: x = {x.mean() * 1e6:.2f} um (pp {np.ptp(x) * 1e6:.2f} um), '
          f'p_A - p_B = {dp.mean() / 1e5:.2f} bar (ideal {load / plant.p.A_p / 1e5:.2f}), '
          f'max p = {max(run["p_a"].max(), run["p_b"].max()) / 1e5:.1f} bar, '
          f'motor speed {run["w"][0][last].mean():.2f} rad/s')
    assert abs(x.mean()) < 60e-6 and np.ptp(x) < 20e-6          # settled at the reference
    assert max(run['p_a'].max(), run['p_b'].max()) < relief     # relief never cracks
    assert abs(dp.mean() * plant.p.A_p / load - 1) < 0.02       # load carried by p_D
    # the motor turns to make up the leakage at ~89 bar (Fig. 3.44): C_eq p_D / D_p
    expected = plant.p.C_eq * load / plant.p.A_p / plant.p.D_p
    assert 0.5 * expected < run['w'][0][last].mean() < 2.0 * expected
    # a load pushing towards -x is held by a higher pressure in chamber A
    assert run['p_a'][-1] > run['p_b'][-1]
