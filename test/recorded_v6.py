"""The bundled FTDCR v6 recorded run (``test/data/ftdcr_v6``): its files and its columns.

Used by the tests and by ``benchmarks/bench_calibration.py`` (through ``benchmarks/shared.py``).
"""
from pathlib import Path

from continuum_statics.calibration.recorded_run import ColumnMap

REPO = Path(__file__).resolve().parents[1]
V6_ROBOT = REPO / 'config' / 'ftdcr_v6_robot.yaml'
V6_DATA = REPO / 'test' / 'data' / 'ftdcr_v6'
#: Displacement columns (mm) of the nine servos, in the robot file's cable order; tips in mm.
V6_COLUMNS = ColumnMap(cables=('servo_1_mm', 'servo_20_mm', 'servo_23_mm', 'servo_9_mm',
                               'servo_6_mm', 'servo_11_mm', 'servo_24_mm', 'servo_2_mm',
                               'servo_3_mm'),
                       kind='displacement', scale=1e-3, tip_scale=1e-3)
