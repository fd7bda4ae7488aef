"""The calibrated robot file: the input file's YAML with the fitted robot's values in place.

Keys the calibration cannot change keep their text (``poisson_ratio``, ``solver``, names, limits);
a comment header says what was fitted from which data and the errors it reached.
"""
import datetime

import numpy as np
import yaml

from continuum_statics.core.description.routing import GuideOffsets, Helix

#: Fit names that change the ``tendons`` blocks.
TENDON_NAMES = ('cable_zero', 'stiffness', 'cable_stiffness', 'pretension', 'friction',
                'stick_length')


def write_robot_file(output, robot_file, robot, fit, header, uncertainty=None):
    """Write ``robot_file``'s content with ``robot``'s values and a provenance header.

    :param robot: the calibrated :class:`Robot`, in the file's frame
    :param fit: the fitted names (which tendon values and section lengths to write)
    :param header: comment lines (without ``#``) after the date line
    :param uncertainty: a measured :class:`ModelUncertainty` for ``model_uncertainty``
    """
    with open(robot_file, encoding='utf-8') as stream:
        document = yaml.safe_load(stream)
    description = robot.description
    document['base'] = dict(document['base'], position=_rounded(description.base_position),
                            orientation=_rounded(description.base_orientation, 9))
    document['gravity'] = _rounded(description.gravity, 6)
    if 'tip_marker' in document or np.any(robot.tip_marker != 0.0):
        document['tip_marker'] = _rounded(robot.tip_marker, 6)
    rod = robot.rod
    document['rod'] = dict(document['rod'], youngs_modulus=_number(rod.youngs_modulus),
                           density=_number(rod.density))
    if 'shear_modulus' in document['rod']:
        document['rod']['shear_modulus'] = _number(rod.shear_modulus)
    if 'extension_shear' in fit:
        document['rod']['axial_rigidity'] = _number(rod.axial_rigidity)
        document['rod']['shear_rigidity'] = _number(rod.shear_rigidity)
    holders = document.get('sections') or [document]
    if 'section_length' in fit:
        document['rod']['length'] = _number(rod.length, 9)
        for holder, section in zip(holders, robot.sections):
            holder['guides'] = _rounded(section.guides, 7)
    if 'section_bending' in fit:
        for holder, section in zip(holders, robot.sections):
            holder['bending_scale'] = _number(section.bending_scale)
    if 'damping' in fit:
        document['rod']['damping'] = {'bending': _number(rod.bending_damping),
                                      'shear': _number(rod.shear_damping)}
    if 'disk_mass' in fit:
        for holder, section in zip(holders, robot.sections):
            holder['disk_mass'] = _number(section.disk_mass)
    if set(fit) & set(TENDON_NAMES):
        _write_tendons(document, holders, robot)
    if uncertainty is not None:
        document['model_uncertainty'] = {
            key: _number(getattr(uncertainty, key)) for key in (
                'tip_force', 'section_moment', 'cable_length', 'base_position',
                'correlation_time', 'drift', 'drift_time', 'point_noise')}
    routes = robot.description.routes()
    j = 0
    for holder in holders:
        for cable in holder.get('cables') or []:
            _write_route(cable, routes[j])
            j += 1
    lines = ['Calibrated by `python -m continuum_statics calibrate` on %s UTC'
             % datetime.datetime.now(datetime.timezone.utc).strftime('%Y-%m-%d %H:%M')]
    lines += list(header)
    text = ''.join('# %s\n' % line for line in lines)
    text += yaml.safe_dump(document, sort_keys=False, default_flow_style=None, width=99)
    with open(output, 'w', encoding='utf-8') as stream:
        stream.write(text)


def _write_tendons(document, holders, robot):
    """Tendon values: per section where a section's cables agree, else on each cable."""
    tendons = robot.tendons
    top = dict(document.get('tendons') or {})
    if np.all(tendons.friction == tendons.friction[0]):
        top['friction'] = _number(tendons.friction[0])
    stick = tendons.stick_length
    if np.all(stick == stick[0]) and (stick[0] or 'stick_length' in top):
        top['stick_length'] = _number(stick[0])  # one value: no section or cable keeps its own
        for holder in holders:
            for entry in [holder.get('tendons') or {}] + list(holder.get('cables') or []):
                if entry is not top:
                    entry.pop('stick_length', None)
    document['tendons'] = top
    j = 0
    for holder, section in zip(holders, robot.sections):
        block = dict(holder.get('tendons') or {}) if holder is not document else top
        cables = list(section.cable_indices)
        per_cable = []  # keys whose values differ within the section: on each cable entry
        for key in ('stiffness', 'pretension'):
            values = getattr(tendons, key)[cables]
            if not np.all(np.isfinite(values)) or (key == 'pretension' and not np.any(values)):
                continue
            if np.all(values == values[0]):
                block[key] = _number(values[0])
            else:
                per_cable.append(key)
        if holder is not document:
            holder['tendons'] = block
        for cable in holder.get('cables') or []:
            for key in per_cable:
                cable[key] = _number(getattr(tendons, key)[j])
            if tendons.zero_offset[j] != 0.0:
                cable['zero_offset'] = _number(tendons.zero_offset[j])
            j += 1


def _number(value, digits=6):
    return float('%.*g' % (digits, value))


def _rounded(values, digits=9):
    return [_number(v, digits) for v in np.asarray(values, dtype=float)]


def _write_route(cable, route):
    """Write a cable's route into its file entry, in the form the file gave it."""
    if isinstance(route, Helix):
        cable['helix'] = {'radius': _number(route.radius, 9),
                          'start_angle': _number(route.start_angle, 9),
                          'turns_per_metre': _number(route.turns_per_metre, 9)}
    elif isinstance(route, GuideOffsets):
        cable['offsets'] = [_rounded(offset, 7) for offset in route.offsets]
    else:
        cable['offset'] = _rounded(route.offset, 7)
