"""Where the package's files are: the share directory, robot files, config/ (no ROS).

The nodes' ``robot_file`` parameter, the tools and the benchmarks resolve paths here. The ament
index is asked when it is there (a colcon install); otherwise the source tree is the share
directory (a pip install -e).
"""
import os
from pathlib import Path

PACKAGE = 'continuum_statics'


def share_dir():
    """Return the package's share directory (colcon install) or the source tree (pip -e)."""
    try:
        from ament_index_python.packages import get_package_share_directory
        path = Path(get_package_share_directory(PACKAGE))
        if (path / 'config').is_dir():
            return path
    except Exception:  # not in an ament index (pip route), or AMENT_PREFIX_PATH unset
        pass
    return Path(__file__).resolve().parents[1]


def default_robot_file():
    """Return the tendon robot file shipped in ``config/``."""
    return str(share_dir() / 'config' / 'tendon_robot.yaml')


def resolve_config_path(path):
    """Return ``path`` if it exists, else the same relative path under the share directory."""
    path = os.path.expanduser(str(path))
    if os.path.isabs(path) or os.path.exists(path):
        return path
    candidate = share_dir() / path
    return str(candidate) if candidate.exists() else path


def check_robot_file(value):
    """Reason why ``value`` is not a readable robot file, or None."""
    if not value:
        return 'robot_file must name a robot description YAML file'
    path = resolve_config_path(value)
    if not os.path.isfile(path):
        return 'robot_file %r does not exist' % value
    return None


def load_robot_file(path, logger=None):
    """Load the robot description named by a ``robot_file`` parameter (ValueError when bad).

    :param logger: when given, each implausible value of the file is logged as a warning
    """
    from continuum_statics import load_robot
    robot = load_robot(resolve_config_path(path))
    for warning in robot.description.warnings if logger is not None else ():
        logger.warning('robot file %s: %s' % (path, warning))
    return robot


def config_file(name):
    """Return ``config/<name>``: from the source tree when there, else the share directory."""
    source = Path(__file__).resolve().parents[1] / 'config' / name
    return source if source.exists() else share_dir() / 'config' / name
