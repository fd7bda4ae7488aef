"""Style gate, as ament_flake8 and ament_pep257 are in ROS packages (99 columns, docstrings)."""
import shutil
import subprocess
import sys

from conftest import REPO
import pytest

pytestmark = pytest.mark.ros  # starts DDS or a process


def _ruff():
    exe = shutil.which('ruff', path=str(REPO / '.venv' / 'bin')) or shutil.which('ruff')
    if exe is None:
        pytest.skip('ruff is not installed (pip route installs it from requirements.txt)')
    return exe


@pytest.mark.linter
def test_flake8_and_pep257():
    result = subprocess.run(
        [_ruff(), 'check', '--no-cache', '.'], cwd=REPO, capture_output=True, text=True)
    sys.stdout.write(result.stdout)
    assert result.returncode == 0, 'ruff found style errors:\n' + result.stdout + result.stderr
