"""The bench calibration: drift model file, warm-start state and a one-page report per unit, from
warm-up or drive logs of any format (`gyro-thermal-comp calibrate`, docs/sources.md).

    from gyro_thermal_comp.calibration import calibrate_fleet, calibrate_unit
    cal = calibrate_unit(['bench.ulg'])                        # one unit, plain data
    calibrate_fleet(logs, 'out', unit=r'(unit\\d+)')          # many units, files per unit
"""
from .fleet import FILES, UnitOutcome, calibrate_fleet, group_logs, unit_key
from .unit import CalibrationError, UnitCalibration, calibrate_unit

__all__ = ['FILES', 'CalibrationError', 'UnitCalibration', 'UnitOutcome', 'calibrate_fleet', 'calibrate_unit',
           'group_logs', 'unit_key']
