"""What the benchmarks share with the tests (both outside the installed package).

The bundled v6 run's columns (``test/recorded_v6.py``) and the robot-like motion and SciPy
baseline (``test/reference_motion.py``) live beside the tests that check them; benchmarks import
them from here, so ``test/`` is put on the path in one place.
"""
from pathlib import Path
import sys

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'test'))

from obstacle_scene import CLEARANCE, scene  # noqa: E402
from recorded_v6 import V6_COLUMNS, V6_DATA, V6_ROBOT  # noqa: E402
from reference_motion import RATE, SPEED, motion, scipy_estimate  # noqa: E402

__all__ = ['CLEARANCE', 'scene', 'V6_COLUMNS', 'V6_DATA', 'V6_ROBOT', 'RATE', 'SPEED', 'motion',
           'scipy_estimate']
