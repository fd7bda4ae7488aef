"""The home file: actuator positions at the straight pose, kept across restarts (YAML, no ROS).

Written by ``cable_driver/set_home``, read at every driver start ahead of the zero parameter.
"""
import os
from pathlib import Path
import time

import yaml


def load_home_file(path, backend_name, zero_option, cable_names):
    """Return the zero positions stored in ``path`` for this backend, or None if no file.

    :raises ValueError: a file that is not for this backend or these cables (says which)
    """
    path = Path(path).expanduser()
    if not path.is_file():
        return None
    try:
        data = yaml.safe_load(path.read_text()) or {}
    except (OSError, yaml.YAMLError) as error:
        raise ValueError('home_file %s: %s' % (path, error)) from None
    if not isinstance(data, dict) or data.get('backend') != backend_name:
        raise ValueError('home_file %s was written for backend %r, not %r' % (
            path, data.get('backend') if isinstance(data, dict) else None, backend_name))
    if list(data.get('cable_names', [])) != list(cable_names):
        raise ValueError('home_file %s is for cables %s, not %s' % (
            path, data.get('cable_names'), list(cable_names)))
    zeros = data.get(zero_option)
    if not isinstance(zeros, list) or len(zeros) != len(cable_names):
        raise ValueError('home_file %s: %s needs %d values' % (path, zero_option,
                                                               len(cable_names)))
    return zeros


def home_option(path, backend_cls, cable_names):
    """Return {the backend's zero option: the home file's zeros}, or {} when there are none.

    Empty for no ``path``, a backend without homing, a robot without cables, or no file yet.
    """
    option = backend_cls.zero_option
    if not (path and option and cable_names):
        return {}
    zeros = load_home_file(path, backend_cls.name, option, cable_names)
    return {} if zeros is None else {option: zeros}


def write_home_file(path, backend_name, zero_option, cable_names, zeros):
    """Write the home positions atomically (a crash never leaves half a file)."""
    path = Path(path).expanduser()
    path.parent.mkdir(parents=True, exist_ok=True)
    data = {'backend': backend_name, 'cable_names': list(cable_names),
            zero_option: [z.item() if hasattr(z, 'item') else z for z in zeros],
            'written': time.strftime('%Y-%m-%dT%H:%M:%S%z')}
    tmp = path.with_name(path.name + '.tmp')
    tmp.write_text('# straight pose of the cable actuators, written by cable_driver/set_home\n'
                   + yaml.safe_dump(data, sort_keys=False))
    os.replace(tmp, path)
