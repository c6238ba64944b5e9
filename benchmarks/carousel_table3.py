"""Issue 5 evaluation, full length: the paper's Table 3 (eps, dV, dS at t = 300 s) for static,
vertical-axis and horizontal-axis modulation (+ the two-position flip), the residuals carouseling
does not remove, spin-rate removal with/without encoder, and the carousel-fed thermal model.

    .venv/bin/python benchmarks/carousel_table3.py [--seed 4]

Simulated MTi-1 runs (gyro_thermal_comp.sim), 100 Hz, demodulated by CarouselDemodulator. Every
modulated column has a full 300 s window of steady rotation (runs of 380 s: 60 s still, 5 s spin-up,
10 s settling). Exits 1 if a target of issue 5 fails. ~10 s on one core.
"""
from __future__ import annotations

import argparse
import sys

import numpy as np

from gyro_thermal_comp.carousel import CarouselConfig, FlipConfig
from gyro_thermal_comp.carousel.evaluation import (CAROUSEL_TO_BODY, Truth, axial_scale_factor_residual,
                                                   record_truth_errors, run_demodulator, sensor_drift_after,
                                                   spin_rate_errors, static_errors, static_twin, unremoved_for_run)
from gyro_thermal_comp.carousel.metrics import error_growth, format_table3, table3
from gyro_thermal_comp.carousel.thermal_link import CarouselThermalLink
from gyro_thermal_comp.sim import make_config, simulate
from gyro_thermal_comp.thermal.temperature_rate import TemperatureRateEstimator

DEG = 180 / np.pi
T_EVAL_S = 300.0
WINDOW = (75.0, 375.0)           # steady rotation: after still (60 s), spin-up (5 s) and 10 s settling
DURATION_S = 380.0
TARGETS = {'inplane_reduction': 20.0, 'spin_encoder_pct': 0.05, 'spin_gyro_pct': 0.5, 'flip_reduction': 10.0,
           'thermal_ratio': 0.10}


def demod_config(scenario: str, **kw) -> CarouselConfig:
    m = CAROUSEL_TO_BODY[scenario]
    return CarouselConfig.turntable(carousel_to_body=tuple(map(tuple, m)),
                                    flip=FlipConfig(enabled=scenario == 'carousel_flip'), **kw)


def run(scenario: str, seed: int, **cfg_kw):
    cfg = make_config(scenario, seed=seed, duration_s=DURATION_S)
    chunks = list(simulate(cfg))
    recs, meas, flips, _ = run_demodulator(chunks, demod_config(scenario, **cfg_kw))
    return cfg, chunks, recs, flips


def table_part(seed: int, failures: list) -> None:
    errors, static_by_col, rows = {}, {}, []
    print(f'== Table 3 (seed {seed}; eps/dV/dS at t = {T_EVAL_S:.0f} s from mean errors over the {WINDOW[1] - WINDOW[0]:.0f} s '
          'window; rows: X, Y in the rotation plane, Z = spin axis; static = same unit, table not turning)')
    for col, scen in (('vertical_axis', 'carousel_vertical'), ('horizontal_axis', 'carousel_horizontal'),
                      ('flip_vertical', 'carousel_flip')):
        cfg, chunks, recs, flips = run(scen, seed)
        sw, sa = static_errors(static_twin(cfg), *WINDOW)
        dw, da, dur = record_truth_errors(Truth(cfg), recs, *WINDOW, carousel_axes=CAROUSEL_TO_BODY[scen])
        if col == 'vertical_axis':
            errors['static'] = (sw, sa)
        errors[col] = (dw, da)
        static_by_col[col] = (sw, sa)
        sf_res = axial_scale_factor_residual(cfg, recs, *WINDOW)
        parts = unremoved_for_run(cfg, recs, sw, sa, CAROUSEL_TO_BODY[scen], *WINDOW)
        rows.append((col, cfg, recs, flips, sw, sa, dw, da, dur, sf_res, parts))
    tab = table3(errors, T_EVAL_S)
    print(format_table3(tab))

    print('\n-- eps reduction |static| / |modulated| per axis (each column against its own static mount)')
    for col, cfg, recs, flips, sw, sa, dw, da, dur, sf_res, parts in rows:
        ratio = np.abs(sw) / np.abs(dw)
        print(f'{col:16s} ratio X {ratio[0]:8.1f}  Y {ratio[1]:8.1f}  Z {ratio[2]:8.2f}   (window {dur:.0f} s, '
              f'{len(flips)} flips)')
        if col in ('vertical_axis', 'horizontal_axis') and min(ratio[:2]) < TARGETS['inplane_reduction']:
            failures.append(f'{col}: in-plane reduction {min(ratio[:2]):.1f}x < {TARGETS["inplane_reduction"]}x')
        if col == 'flip_vertical':
            bias_part = dw.copy()
            bias_part[2] -= sf_res
            r_bias = np.abs(sw) / np.abs(bias_part)
            print(f'{"":16s} axial without the scale-factor x spin residual ({sf_res * DEG * T_EVAL_S:+.3f} deg '
                  f'at 300 s, shown below): Z {r_bias[2]:.1f}x   -> all three axes min {min(r_bias):.1f}x')
            if min(r_bias) < TARGETS['flip_reduction']:
                failures.append(f'flip: min axis reduction {min(r_bias):.1f}x < {TARGETS["flip_reduction"]}x')

    print('\n-- residuals carouseling does not remove (predicted from the unit\'s true coefficients, eps at 300 s, deg;'
          ' carousel axes X, Y, Z)')
    for col, cfg, recs, flips, sw, sa, dw, da, dur, sf_res, parts in rows:
        if col == 'flip_vertical':
            print(f'{col:16s} scale_factor x spin (axial imu axis per flip position): Z {sf_res * DEG * T_EVAL_S:+.3f}')
            continue
        for name in ('axial_bias', 'scale_factor', 'sensor_axis_misalignment', 'inplane_scale_factor',
                     'g_sensitivity', 'total'):
            eps = error_growth(parts[name][0], parts[name][1], T_EVAL_S)['eps_rad'] * DEG
            print(f'{col:16s} {name:26s} X {eps[0]:+9.4f}  Y {eps[1]:+9.4f}  Z {eps[2]:+9.3f}')
        eps = error_growth(dw, da, T_EVAL_S)['eps_rad'] * DEG
        print(f'{col:16s} {"measured (demodulated)":26s} X {eps[0]:+9.4f}  Y {eps[1]:+9.4f}  Z {eps[2]:+9.3f}')


def spin_part(seed: int, failures: list) -> None:
    print('\n== spin-rate removal, carousel_vertical: (Omega_est - Omega_true) / Omega_true per revolution')
    for label, kw, target in (('encoder', {}, TARGETS['spin_encoder_pct']),
                              ('no encoder (gyro angle)', {'angle_source': 'gyro'}, TARGETS['spin_gyro_pct'])):
        cfg, chunks, recs, _ = run('carousel_vertical', seed, **kw)
        rel = spin_rate_errors(Truth(cfg), [r for r in recs if r.t_s - r.duration_s >= WINDOW[0]]) * 100
        print(f'{label:24s} mean {np.mean(rel):+.2e} %  max |.| {np.max(np.abs(rel)):.2e} %  ({len(rel)} revolutions; '
              f'target <= {target} %)')
        if np.max(np.abs(rel)) > target:
            failures.append(f'spin-rate removal ({label}) {np.max(np.abs(rel)):.4f} % > {target} %')


def thermal_part(seed: int, failures: list, verbose: bool = True) -> float:
    """carousel_vertical, 25 -> 40 degC (tau 300 s), spinning 60..665 s, then stopped for 300+ s; no
    magnetometer used. The link learns from the revolutions before the stop and the start-up still
    period, then predicts the in-plane drift from the live temperature only."""
    stop_s = 665.0
    cfg = make_config('carousel_vertical', seed=seed, duration_s=stop_s + 5 + 300 + 10,
                      params={'temp_start_c': 25.0, 'temp_peak_c': 40.0, 'warmup_tau_s': 300.0, 'spin_stop_s': stop_s})
    chunks = list(simulate(cfg))
    recs, meas, _, _ = run_demodulator(chunks, CarouselConfig.turntable())
    link, spin = still_and_learn(cfg, chunks, recs, meas, stop_s)
    t_c = np.concatenate([c.temperature.t for c in chunks])
    temp_c = np.concatenate([c.temperature.temp_c for c in chunks])
    t0 = stop_s + cfg.params['spinup_s'] + 2.0           # table at rest
    td, drift = sensor_drift_after(Truth(cfg), chunks, t0, t0 + 300.0)
    est = TemperatureRateEstimator(window_s=link.config.temperature_rate_window_s).update(t_c, temp_c)
    pred = link.drift(np.interp(td, est.t, est.temp_c), np.interp(td, est.t, est.rate_c_s))
    unc = np.trapezoid(drift[:, :2], td, axis=0)
    res = np.trapezoid(drift[:, :2] - pred, td, axis=0)
    ratio = np.abs(res) / np.abs(unc)
    if verbose:
        print(f'\n== carousel-fed thermal model (seed {seed}; {len(meas)} revolution measurements, temperature '
              f'{temp_c.min():.1f} -> {temp_c.max():.1f} degC, table stops at {stop_s:.0f} s, no magnetometer)')
        print(f'heading-type error over the 300 s after the stop, deg: uncompensated x {unc[0] * DEG:+.2f} '
              f'y {unc[1] * DEG:+.2f}; with the learned model x {res[0] * DEG:+.3f} y {res[1] * DEG:+.3f}; '
              f'ratio x {ratio[0] * 100:.1f} % y {ratio[1] * 100:.1f} % (target <= {TARGETS["thermal_ratio"] * 100:.0f} %)')
        print('learned (rad/s, per degC, per degC/s, spin coupling):',
              {ax: {k: f'{v:.3g}' for k, v in p.items()} for ax, p in link.parameters().items()})
    if np.max(ratio) > TARGETS['thermal_ratio']:
        failures.append(f'thermal link: residual {np.max(ratio) * 100:.1f} % > {TARGETS["thermal_ratio"] * 100:.0f} %')
    return float(np.max(ratio))


def still_and_learn(cfg, chunks, recs, meas, stop_s: float):
    """Feed the link: the start-up still period's raw in-plane mean (spin 0), then every revolution
    measurement before the stop with its revolution's spin rate."""
    from gyro_thermal_comp.carousel.thermal_link import still_measurement
    link = CarouselThermalLink()
    link.add_still(*still_measurement(chunks, 2.0, cfg.params['still_s'] - 2.0))
    spin = {round(r.t_s, 6): r.spin_rate_rad_s for r in recs}
    link.add([m for m in meas if m.t_s < stop_s], lambda m: spin.get(round(m.t_s, 6), 2 * np.pi / m.duration_s))
    return link, spin


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--seed', type=int, default=4)
    args = ap.parse_args(argv)
    failures: list[str] = []
    table_part(args.seed, failures)
    spin_part(args.seed, failures)
    thermal_part(args.seed, failures)
    print('\n' + ('ALL TARGETS MET' if not failures else 'FAILED:\n  ' + '\n  '.join(failures)))
    return 1 if failures else 0


if __name__ == '__main__':
    sys.exit(main())
