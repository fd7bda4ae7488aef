"""What a calibration may fit: the parameter blocks, the search vector and the candidate robot.

One table for both data kinds. A block is one fit name's slice of the search vector; its
variables are in the optimiser's units (angles in rad or deg, log factors for moduli and
stiffness) and :meth:`SearchVector.values` turns them into the robot file's units.

Fit names and the data kinds that can see them (``run``: a recorded run replayed through
``solve_lengths``; ``tip_loads``: static rows of known tip loads):

=====================  ==========  ==============================================================
name                   kinds       variables
=====================  ==========  ==============================================================
``registration``       run         tracker <- base rotation and position (closed form, no vars)
``base_position``      run         the base position alone (closed form, no vars)
``section_rotation``   run         rad per section: its hole pattern about the backbone
``cable_angle``        run         rad per cable, on top of its section's rotation
``cable_zero``         run         m per cable: ``zero_offset`` (homed too long: > 0)
``stiffness``          run         log EA (N) per section
``cable_stiffness``    run         log EA (N) per cable
``pretension``         run         N per section
``friction``           run         one capstan coefficient for every cable
``stick_length``       run         m, one for every cable: travel over which friction turns over
``section_length``     run         log factor per section on its length (guides scale with it)
``section_bending``    run         log of each section's ``bending_scale`` (factor on E I, G J)
``disk_mass``          run         kg per section: the mass of each of its guide disks
``extension_shear``    run         log factors on the backbone's E A and G A (axial, shear)
``youngs_modulus``     both        log factor on E (G follows, see :func:`scaled_rod`)
``density``            both        log factor on the density
``gravity``            run         m/s^2 in the tracker frame (|g| goes into the density)
``tip_marker``         run         m, the tracked point on the tip frame
``base_roll`` ...      tip_loads   deg about the fixed base axes (URDF rpy) on the file's base
``cable_offset_scale`` tip_loads   factor on every hole offset
=====================  ==========  ==============================================================
"""
import dataclasses
import math

import numpy as np

from continuum_statics.core.description.robot_file import BENDING_SCALE_RANGE
from continuum_statics.core.description.tendons import Tendons
from continuum_statics.core.robot import Robot

RUN_PARAMETERS = ('registration', 'base_position', 'section_rotation', 'cable_angle',
                  'cable_zero', 'stiffness', 'pretension', 'friction', 'youngs_modulus',
                  'density', 'gravity', 'tip_marker', 'cable_stiffness', 'section_length',
                  'section_bending', 'disk_mass', 'extension_shear', 'stick_length')
TIP_LOAD_PARAMETERS = ('youngs_modulus', 'density', 'base_roll', 'base_pitch', 'base_yaw',
                       'cable_offset_scale')
DEFAULT_FIT = ('registration', 'section_rotation', 'cable_angle', 'cable_zero', 'stiffness',
               'friction')
BASE_ANGLES = ('base_roll', 'base_pitch', 'base_yaw')
#: Fit names solved in closed form for every candidate (no search variables).
CLOSED_FORM = ('registration', 'base_position')
#: Stiffness start (times E I / (L r), the tension that bends the robot by about 1 rad) for a
#: robot file whose tendons are inextensible: a stretch of 0.1 % at that tension.
STIFFNESS_START = 1000.0
#: Bounds of a log factor (e^+-3: 0.05 to 20 times the file's value).
LOG_FACTOR_BOUND = 3.0
#: Heaviest guide disk a fit may find (kg): a 3-D-printed disk of a lab robot weighs grams.
DISK_MASS_BOUND = 0.05
#: Start of a disk mass the file does not give (kg): least_squares scales its first trust
#: region by the start (x_scale='jac'), and a start on the bound (0) would make it vanish.
DISK_MASS_START = 1e-4
#: Bounds of the log factors on E A and G A (a spring or slotted-tube backbone is 1000 times
#: softer in extension and shear than the solid rod of its diameter).
RIGIDITY_BOUND = 7.0
#: Longest stick zone a fit may find (m of motor travel) and its start when the file has none
#: (a start on the bound 0 would give least_squares no trust region, see DISK_MASS_START).
STICK_LENGTH_BOUND = 0.02
STICK_LENGTH_START = 1e-4
#: Bounds of a section length's log factor (+-20 %: a wrong section length is a few mm).
SECTION_LENGTH_BOUND = 0.2
#: Finite-difference step of each name's variables (optimiser units): large enough that the
#: tip moves far more than a replay's tolerance (run_model.REPLAY_TOLERANCE, 1e-12 m of
#: cable; a node's is 1e-9 m), small enough to stay linear. A friction step of 0.01 changes a
#: tension by 6 % over a full turn of wrap.
DIFFERENCE_STEPS = {'section_rotation': 1e-4, 'cable_angle': 1e-4, 'cable_zero': 1e-6,
                    'stiffness': 1e-4, 'cable_stiffness': 1e-4, 'pretension': 1e-3,
                    'friction': 1e-2, 'section_length': 1e-4, 'section_bending': 1e-4,
                    'disk_mass': 1e-5, 'extension_shear': 1e-4, 'stick_length': 1e-5,
                    'youngs_modulus': 1e-4,
                    'density': 1e-4, 'gravity': 1e-3, 'tip_marker': 1e-6, 'base_roll': 1e-3,
                    'base_pitch': 1e-3, 'base_yaw': 1e-3, 'cable_offset_scale': 1e-4}
#: Blocks whose variables are logarithms of their values.
LOG_VARIABLES = ('stiffness', 'cable_stiffness', 'youngs_modulus', 'density', 'section_length',
                 'section_bending', 'extension_shear')
#: Units of each name's values (after :meth:`SearchVector.values`).
UNITS = {'section_rotation': 'rad', 'cable_angle': 'rad', 'cable_zero': 'm', 'stiffness': 'N',
         'cable_stiffness': 'N', 'pretension': 'N', 'friction': '1', 'section_length': 'm',
         'section_bending': '1', 'disk_mass': 'kg', 'extension_shear': 'N', 'stick_length': 'm',
         'youngs_modulus': 'Pa', 'density': 'kg/m^3', 'gravity': 'm/s^2', 'tip_marker': 'm',
         'base_roll': 'deg', 'base_pitch': 'deg', 'base_yaw': 'deg', 'cable_offset_scale': '1'}


@dataclasses.dataclass(frozen=True)
class Block:
    """A slice of the search vector: one fit name's variables (optimiser units)."""

    name: str
    start: np.ndarray
    low: np.ndarray
    high: np.ndarray
    index: slice


def check_names(names, kind):
    """Raise ``ValueError`` naming the fit names ``kind`` ('run' or 'tip_loads') cannot fit."""
    known = RUN_PARAMETERS if kind == 'run' else TIP_LOAD_PARAMETERS
    unknown = [name for name in names if name not in known]
    if unknown:
        what = 'for a recorded run' if kind == 'run' else 'for tip-load rows'
        raise ValueError('unknown parameter(s) %s %s; fittable: %s'
                         % (', '.join(unknown), what, ', '.join(known)))


class SearchVector:
    """The fit names' variables of a robot: blocks, start, bounds and values in file units.

    :param robot: the robot file's :class:`Robot` (the start of every variable)
    :param fit: fit names (any order; kept in table order, duplicates dropped)
    :param shear_fixed: the file gives ``shear_modulus``: G stays when E is fitted
    """

    def __init__(self, robot, fit, shear_fixed=False):
        order = RUN_PARAMETERS + TIP_LOAD_PARAMETERS
        self.robot = robot
        self.fit = [name for name in dict.fromkeys(order) if name in fit]
        self.registered = 'registration' in self.fit
        self.shear_fixed = shear_fixed
        self.blocks = self._blocks()
        self.size = sum(b.start.size for b in self.blocks)

    def _starts(self):
        robot, tendons = self.robot, self.robot.tendons
        n_sections, n_cables = len(robot.sections), len(robot.cable_names)
        radius = np.hypot(robot.cable_offsets[:, 0], robot.cable_offsets[:, 1])
        t_ref = (robot.c[0] / (robot.length * float(np.mean(radius)))
                 if n_cables and np.mean(radius) > 0 else 1.0)
        stiffness = np.array([np.mean(tendons.stiffness[list(s.cable_indices)])
                              if s.cable_indices else np.inf for s in robot.sections])
        stiffness[~np.isfinite(stiffness)] = STIFFNESS_START * t_ref
        per_cable = np.where(np.isfinite(tendons.stiffness), tendons.stiffness,
                             STIFFNESS_START * t_ref)
        first = 1 if self.registered else 0
        log = (np.zeros(1), -LOG_FACTOR_BOUND, LOG_FACTOR_BOUND)
        return {
            'section_rotation': (np.zeros(n_sections - first), -math.pi, math.pi),
            'cable_angle': (np.zeros(n_cables), -0.5, 0.5),
            'cable_zero': (np.array(tendons.zero_offset), -0.02, 0.02),
            'stiffness': (np.log(stiffness), np.log(stiffness) - 9.0, np.log(stiffness) + 9.0),
            'cable_stiffness': (np.log(per_cable), np.log(per_cable) - 9.0,
                                np.log(per_cable) + 9.0),
            'pretension': (np.array([np.mean(tendons.pretension[list(s.cable_indices)])
                                     if s.cable_indices else 0.0 for s in robot.sections]),
                           0.0, 100.0 * t_ref),
            'friction': (np.array([float(np.mean(tendons.friction))]), 0.0, 1.0),
            'stick_length': (np.array([max(float(np.mean(tendons.stick_length)),
                                           STICK_LENGTH_START)]), 0.0, STICK_LENGTH_BOUND),
            'section_length': (np.zeros(n_sections), -SECTION_LENGTH_BOUND,
                               SECTION_LENGTH_BOUND),
            'section_bending': (np.log([s.bending_scale for s in robot.sections]),
                                np.log(BENDING_SCALE_RANGE[0]), np.log(BENDING_SCALE_RANGE[1])),
            'disk_mass': (np.maximum([s.disk_mass for s in robot.sections], DISK_MASS_START),
                          0.0, DISK_MASS_BOUND),
            'extension_shear': (np.zeros(2), -RIGIDITY_BOUND, RIGIDITY_BOUND),
            'youngs_modulus': log,
            'density': log,
            'gravity': (np.array(robot.gravity, dtype=float), -100.0, 100.0),
            'tip_marker': (np.array(robot.tip_marker, dtype=float),
                           robot.tip_marker - 0.1 * robot.length,
                           robot.tip_marker + 0.1 * robot.length),
            'base_roll': (np.zeros(1), -30.0, 30.0),
            'base_pitch': (np.zeros(1), -30.0, 30.0),
            'base_yaw': (np.zeros(1), -30.0, 30.0),
            'cable_offset_scale': (np.ones(1), 0.5, 2.0),
        }

    def _blocks(self):
        starts, blocks, at = self._starts(), [], 0
        for name in self.fit:
            if name in CLOSED_FORM:
                continue
            start, low, high = starts[name]
            size = start.size
            blocks.append(Block(name, start, np.broadcast_to(low, size).astype(float),
                                np.broadcast_to(high, size).astype(float),
                                slice(at, at + size)))
            at += size
        return blocks

    def start(self):
        """Search vector of the robot file's values."""
        return np.concatenate([b.start for b in self.blocks]) if self.blocks else np.zeros(0)

    def steps(self):
        """Finite-difference step of every search variable (:data:`DIFFERENCE_STEPS`)."""
        if not self.blocks:
            return np.zeros(0)
        return np.concatenate([np.full(b.start.size, DIFFERENCE_STEPS[b.name])
                               for b in self.blocks])

    def bounds(self):
        """(low, high) of the search vector."""
        if not self.blocks:
            return np.zeros(0), np.zeros(0)
        return (np.concatenate([b.low for b in self.blocks]),
                np.concatenate([b.high for b in self.blocks]))

    def values(self, x):
        """Fit name -> its values in file units (arrays; log variables become N, Pa, m ...)."""
        rod, out = self.robot.rod, {}
        for block in self.blocks:
            v = np.array(x[block.index], dtype=float)
            if block.name in ('stiffness', 'cable_stiffness', 'section_bending'):
                v = np.exp(v)
            elif block.name == 'youngs_modulus':
                v = rod.youngs_modulus * np.exp(v)
            elif block.name == 'density':
                v = rod.density * np.exp(v)
            elif block.name == 'section_length':
                v = section_lengths(self.robot) * np.exp(v)
            elif block.name == 'extension_shear':  # [E A, G A] (N)
                v = self.robot.rod.shear_stiffness[[2, 0]] * np.exp(v)
            out[block.name] = v
        return out

    def derivatives(self, x):
        """Return d value / d variable of every search variable (the chain rule for 1-sigma)."""
        out, values = np.ones(self.size), self.values(x)
        for block in self.blocks:
            if block.name in LOG_VARIABLES:  # value = start e^x
                out[block.index] = values[block.name]
        return out

    def robot_for(self, x):
        """Return the candidate robot of search vector ``x``, in the robot file's frame."""
        return candidate_robot(self.robot, self.values(x), self.registered, self.shear_fixed)


def candidate_robot(robot, values, registered=False, shear_fixed=False):
    """Return ``robot`` with the fitted ``values`` (fit name -> file units) in place.

    ``section_rotation`` turns whole hole patterns (the first section's is the registration's
    roll when ``registered``, so it is not a value then); ``cable_angle`` turns single holes.
    """
    description = robot.description
    changes = {}
    angles = np.zeros(len(robot.cable_names))
    if 'section_rotation' in values:
        turn = values['section_rotation']
        if registered:
            turn = np.concatenate([[0.0], turn])
        for k, section in enumerate(robot.sections):
            angles[list(section.cable_indices)] += turn[k]
    if 'cable_angle' in values:
        angles += values['cable_angle']
    offsets = description.cable_offsets
    if np.any(angles != 0.0):
        offsets = turned(offsets, angles)
    if 'cable_offset_scale' in values:
        offsets = offsets * float(np.ravel(values['cable_offset_scale'])[0])
    if offsets is not description.cable_offsets:
        changes['cable_offsets'] = offsets
        if description.cable_routes:  # offsets and helices turn and scale the same way
            scale = float(np.ravel(values.get('cable_offset_scale', [1.0]))[0])
            changes['cable_routes'] = tuple(
                None if route is None else route.turned(angle, scale)
                for route, angle in zip(description.cable_routes, angles))
    tendons = robot.tendons
    arrays = {f.name: np.array(getattr(tendons, f.name)) for f in dataclasses.fields(Tendons)}
    for k, section in enumerate(robot.sections):
        cables = list(section.cable_indices)
        if 'stiffness' in values:
            arrays['stiffness'][cables] = values['stiffness'][k]
        if 'pretension' in values:
            arrays['pretension'][cables] = values['pretension'][k]
    if 'cable_stiffness' in values:
        arrays['stiffness'][:] = values['cable_stiffness']
    if 'cable_zero' in values:
        arrays['zero_offset'][:] = values['cable_zero']
    if 'friction' in values:
        arrays['friction'][:] = values['friction'][0]
    if 'stick_length' in values:
        arrays['stick_length'][:] = values['stick_length'][0]
    changes['tendons'] = Tendons(**arrays)
    rod = description.rod
    if 'youngs_modulus' in values or 'density' in values:
        rod = scaled_rod(rod, _scalar(values.get('youngs_modulus'), rod.youngs_modulus),
                         _scalar(values.get('density'), rod.density), shear_fixed)
    if 'extension_shear' in values:  # after E: fitted rigidities stay what the run shows
        rod = dataclasses.replace(rod, axial_rigidity=float(values['extension_shear'][0]),
                                  shear_rigidity=float(values['extension_shear'][1]))
    if 'section_length' in values:
        if description.cable_routes:
            raise ValueError('section_length is not fitted on a robot with offsets or helix '
                             'routes (their disks and turns would have to stretch too)')
        changes['sections'], changes['guides'], rod = _stretched(description, rod,
                                                                 values['section_length'])
    if 'section_bending' in values:
        if not robot.description.sections or robot.sections[0].name == 'section_0':
            raise ValueError('section_bending needs a robot file with sections: (one '
                             "section's factor is youngs_modulus)")
        changes['sections'] = tuple(
            dataclasses.replace(section, bending_scale=float(scale)) for section, scale in
            zip(changes.get('sections', description.sections), values['section_bending']))
    if 'disk_mass' in values:
        if not robot.description.sections or robot.sections[0].name == 'section_0':
            raise ValueError('disk_mass needs a robot file with sections:')
        changes['sections'] = tuple(
            dataclasses.replace(section, disk_mass=float(mass)) for section, mass in
            zip(changes.get('sections', description.sections), values['disk_mass']))
    if rod is not description.rod:
        changes['rod'] = rod
    if 'tip_marker' in values:
        changes['tip_marker'] = np.array(values['tip_marker'], dtype=float)
    if set(values) & set(BASE_ANGLES):
        changes['base_orientation'] = base_orientation(
            description.base_orientation, *(_scalar(values.get(n), 0.0) for n in BASE_ANGLES))
    if 'gravity' in values:
        changes['gravity'] = np.array(values['gravity'], dtype=float)
    return Robot(dataclasses.replace(description, **changes))


def scaled_rod(rod, youngs_modulus, density, shear_fixed=False):
    """Return the rod with a new E and density: the one rule for G when E is fitted.

    G follows E (Poisson's ratio kept) unless the robot file gives ``shear_modulus``
    (``shear_fixed``), which then stays as measured; so do given ``axial_rigidity`` and
    ``shear_rigidity``.
    """
    shear = rod.shear_modulus if shear_fixed else (
        rod.shear_modulus * youngs_modulus / rod.youngs_modulus)
    return dataclasses.replace(rod, youngs_modulus=youngs_modulus, shear_modulus=shear,
                               density=density)


def section_lengths(robot):
    """Length of each section along the backbone (m), base to tip."""
    ends = np.array([section.end for section in robot.sections], dtype=float)
    return np.diff(np.concatenate([[0.0], ends]))


def _stretched(description, rod, lengths):
    """Sections, guides and rod of new section ``lengths`` (m): guides scale within each."""
    sections, start, new_start = [], 0.0, 0.0
    for section, length in zip(description.sections, lengths):
        guides = new_start + (np.asarray(section.guides) - start) * (
            float(length) / (section.end - start))
        guides.setflags(write=False)
        sections.append(dataclasses.replace(section, guides=guides))
        start, new_start = section.end, new_start + float(length)
    every = np.concatenate([s.guides for s in sections])
    every.setflags(write=False)
    return tuple(sections), every, dataclasses.replace(rod, length=new_start)


def _scalar(value, default):
    return default if value is None else float(np.ravel(value)[0])


def turned(offsets, angles):
    """Hole offsets (n, 3) turned about the backbone (local z) by ``angles`` (rad)."""
    c, s = np.cos(angles), np.sin(angles)
    out = np.array(offsets, dtype=float)
    out[:, 0] = c * offsets[:, 0] - s * offsets[:, 1]
    out[:, 1] = s * offsets[:, 0] + c * offsets[:, 1]
    return out


def base_orientation(quaternion_xyzw, roll_deg, pitch_deg, yaw_deg):
    """Turn a base orientation about the fixed base axes x, y, z (deg, URDF rpy order).

    R = Rz(yaw) Ry(pitch) Rx(roll) R_file; :returns: unit quaternion [x, y, z, w]
    """
    from scipy.spatial.transform import Rotation
    turn = Rotation.from_euler('xyz', [roll_deg, pitch_deg, yaw_deg], degrees=True)
    quaternion = (turn * Rotation.from_quat(quaternion_xyzw)).as_quat()
    return quaternion / np.linalg.norm(quaternion)


def quaternion(rotation):
    """Return the unit quaternion [x, y, z, w] of a rotation matrix."""
    from scipy.spatial.transform import Rotation
    q = Rotation.from_matrix(rotation).as_quat()
    return q / np.linalg.norm(q)

