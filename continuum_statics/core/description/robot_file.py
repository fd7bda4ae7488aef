"""Robot description files (YAML): parsing and validation into plain, checked values.

Every problem raises ``ValueError`` naming the offending field (``rod.length``,
``cables[2].offset``, ...) and what was expected, so a user can fix the file without reading code.
"""
from dataclasses import dataclass
import math

import numpy as np
import yaml

from continuum_statics.core.description.inputs import mapping
from continuum_statics.core.description.obstacles import parse_obstacles
from continuum_statics.core.description.routing import GuideOffsets, Helix, Straight
from continuum_statics.core.description.sensors import (
    ModelUncertainty,
    parse_model_uncertainty,
    parse_sensors,
)
from continuum_statics.core.description.tendons import TENDON_KEYS, Tendons

#: Plausible backbone materials: Young's modulus (Pa) and density (kg/m^3).
YOUNGS_RANGE = (1e5, 1e13)
MAX_DENSITY = 1e5  # above any metal: an effective density may lump the disks onto the backbone
#: Euler-Bernoulli's first cantilever root (omega_1 = 1.875^2 sqrt(E I / rho A L^4))
FIRST_ROOT = 1.875104
#: Most integration steps over the rod a robot file may ask for.
MAX_STEPS = 2000


@dataclass(frozen=True)
class Rod:
    """Backbone material and cross-section (SI units).

    :ivar length: bending length L (m)
    :ivar diameter: solid circular cross-section diameter (m)
    :ivar youngs_modulus: E (Pa)
    :ivar shear_modulus: G (Pa); G = E / (2 (1 + nu)) when given as Poisson's ratio (the paper's
        text writes E / (1 + nu), an erratum: its number, 20.8 GPa, is E / (2 (1 + nu)))
    :ivar density: rho (kg/m^3)
    :ivar axial_rigidity: EA (N) when measured or fitted (a backbone that is not a solid rod:
        a spring, a tube with slots, disks that slide); None: E A of the solid section
    :ivar shear_rigidity: G A (N) likewise; None: G A of the solid section
    :ivar bending_damping: Kelvin-Voigt damping of bending and torsion (N m^2 s; the file's
        ``damping.bending``): B_bt = it times the identity (Till et al. 2019 eq. 4)
    :ivar shear_damping: Kelvin-Voigt damping of shear and extension (N s; ``damping.shear``):
        B_se = it times the identity
    """

    length: float
    diameter: float
    youngs_modulus: float
    shear_modulus: float
    density: float
    axial_rigidity: float = None
    shear_rigidity: float = None
    bending_damping: float = 0.0
    shear_damping: float = 0.0

    @property
    def area(self):
        """Cross-section area A = pi d^2 / 4 (m^2)."""
        return math.pi * self.diameter ** 2 / 4.0

    @property
    def second_moment(self):
        """Second moment of area I = pi d^4 / 64 (m^4)."""
        return math.pi * self.diameter ** 4 / 64.0

    @property
    def polar_moment(self):
        """Polar moment of area J = pi d^4 / 32 (m^4)."""
        return math.pi * self.diameter ** 4 / 32.0

    @property
    def bending_stiffness(self):
        """Diagonal of C = diag(E I, E I, G J) (N m^2), eq. 7."""
        ei = self.youngs_modulus * self.second_moment
        return np.array([ei, ei, self.shear_modulus * self.polar_moment])

    @property
    def shear_stiffness(self):
        """Diagonal of D = diag(G A, G A, E A) (N), eq. 6 (the rigidities where given)."""
        ga = self.shear_modulus * self.area if self.shear_rigidity is None else self.shear_rigidity
        ea = (self.youngs_modulus * self.area if self.axial_rigidity is None
              else self.axial_rigidity)
        return np.array([ga, ga, ea])

    @property
    def mass_per_length(self):
        """Rho A (kg/m)."""
        return self.density * self.area

    @property
    def first_mode(self):
        """Euler-Bernoulli's first bending angular frequency as a cantilever (rad/s).

        omega_1 = 1.875^2 sqrt(E I / (rho A L^4)), the rod alone (disks and a payload lower
        it); inf for a massless rod.
        """
        if self.mass_per_length <= 0.0:
            return math.inf
        return FIRST_ROOT ** 2 * math.sqrt(self.bending_stiffness[0]
                                          / (self.mass_per_length * self.length ** 4))

    @property
    def first_mode_damping(self):
        """The first mode's damping ratio zeta = B omega_1 / (2 E I) (0 without damping)."""
        if not self.bending_damping or math.isinf(self.first_mode):
            return 0.0
        return self.bending_damping * self.first_mode / (2.0 * self.bending_stiffness[0])


@dataclass(frozen=True)
class SolverSettings:
    """Numerical settings of the robot file's ``solver`` section.

    :ivar steps: RK4 steps over the rod length (the grid also has a node at every guide)
    :ivar max_iterations: iteration limit of the shooting, estimation and tip-goal solvers
    :ivar bvp_tolerance: tip-moment residual of the BVP, relative to E I / L
    :ivar estimate_tolerance: step size (m of cable) below which the shape estimate has converged
    :ivar goal_tolerance: default tip-goal position tolerance (m)
    """

    steps: int = 40
    max_iterations: int = 50
    bvp_tolerance: float = 1e-10
    estimate_tolerance: float = 1e-9
    goal_tolerance: float = 1e-4


@dataclass(frozen=True)
class DynamicsSettings:
    """The robot file's ``dynamics`` section: the defaults of ``Robot.dynamics()``.

    :ivar dt: time step (s)
    :ivar alpha: BDF-alpha parameter in [-0.45, 0] (Till et al. 2019 eq. 13: towards -0.5 the
        trapezoidal rule, little numerical damping; 0 BDF2, the most)
    """

    dt: float = 1e-3
    alpha: float = -0.2


def check_dynamics(dt, alpha, field='dynamics'):
    """Return (dt, alpha) as floats, or raise ValueError naming ``field``."""
    dt = _positive(dt, field + '.dt')
    if dt > MAX_DYNAMICS_DT:
        raise ValueError('%s.dt must be <= %g s (a step is one shooting solve; a control loop '
                         'runs faster), got %g' % (field, MAX_DYNAMICS_DT, dt))
    alpha = _number(alpha, field + '.alpha')
    if not MIN_ALPHA <= alpha <= 0.0:
        raise ValueError('%s.alpha must be in [%g, 0] (Till et al. 2019: 0 is BDF2; their -0.5, '
                         'the trapezoidal rule, damps nothing and lets a spurious mode of the '
                         'discrete rod grow), got %g' % (field, MIN_ALPHA, alpha))
    return dt, alpha


#: Smallest BDF-alpha allowed: at -0.5 (trapezoidal) a mode of the discrete rod grew from
#: round-off (energy x3 in 0.1 s after 0.5 s of an undamped swing); -0.45 kept it 3 s.
MIN_ALPHA = -0.45
#: Longest dynamics time step a robot file may give (s).
MAX_DYNAMICS_DT = 0.1


@dataclass(frozen=True)
class Section:
    """One section: guide disks (arc lengths, m; the last is its end disk) and its cables.

    A cable of this section runs from the base disk (s = 0) through every guide disk of this and
    all earlier sections and ends at :attr:`end`. ``bending_scale`` multiplies the rod's bending
    and torsional stiffness C over the section (its disks stiffen the rod; 1: the bare rod);
    ``disk_mass`` (kg) is the mass of each of its guide disks, a point weight at the disk.
    """

    name: str
    guides: np.ndarray
    cable_indices: tuple
    bending_scale: float = 1.0
    disk_mass: float = 0.0

    @property
    def end(self):
        """Arc length of the end disk (m)."""
        return float(self.guides[-1])


CABLE_MODELS = ('point_moment', 'distributed')


@dataclass(frozen=True)
class RobotDescription:
    """Validated content of a robot file (arrays are read-only).

    ``cable_names``, ``cable_offsets`` and ``cable_length_limits`` list every cable, section by
    section; ``guides`` is every guide disk base to tip; ``warnings`` names implausible fields.
    ``cable_offsets`` is each cable's hole at its end disk; ``cable_routes`` holds, per cable,
    its :mod:`~continuum_statics.core.description.routing` route when the file gives ``offsets`` or
    ``helix`` (None: straight at ``cable_offsets``, what calibration may change).
    ``obstacles`` (:mod:`~continuum_statics.core.description.obstacles`), ``clearance`` (m, the
    tip goals' default) and ``body_radius`` (m; None: the robot's default) are the
    "Obstacles and contact" keys.
    """

    name: str
    rod: Rod
    base_frame_id: str
    base_position: np.ndarray
    base_orientation: np.ndarray
    gravity: np.ndarray
    cable_names: tuple
    cable_offsets: np.ndarray
    cable_length_limits: np.ndarray
    guides: np.ndarray
    solver: SolverSettings
    sections: tuple = ()
    cable_model: str = 'point_moment'
    warnings: tuple = ()
    tendons: Tendons = None
    tip_marker: np.ndarray = None
    cable_routes: tuple = ()
    sensors: tuple = ()
    model_uncertainty: ModelUncertainty = None
    dynamics: DynamicsSettings = DynamicsSettings()
    obstacles: tuple = ()
    clearance: float = 0.0
    body_radius: float = None
    load: tuple = None
    tension_noise: object = None

    def routes(self):
        """One route per cable (:mod:`~continuum_statics.core.description.routing`), straight."""
        routes = self.cable_routes or (None,) * len(self.cable_names)
        return tuple(Straight(np.array(offset)) if route is None else route
                     for route, offset in zip(routes, self.cable_offsets))


_ROD_KEYS = {'length', 'diameter', 'youngs_modulus', 'poisson_ratio', 'shear_modulus', 'density',
             'axial_rigidity', 'shear_rigidity', 'damping'}
_DAMPING_KEYS = {'bending', 'shear'}
_BASE_KEYS = {'frame_id', 'position', 'orientation'}
_ROUTE_KEYS = ('offset', 'offsets', 'helix')
_CABLE_KEYS = {'name', *_ROUTE_KEYS, 'length_limits', 'zero_offset', *TENDON_KEYS}
_HELIX_KEYS = {'radius', 'start_angle', 'turns_per_metre'}
_SECTION_KEYS = {'name', 'guides', 'cables', 'tendons', 'bending_scale', 'disk_mass'}
#: Heaviest guide disk a robot file may give (kg): beyond it the "disk" is a payload.
MAX_DISK_MASS = 1.0
#: Plausible factors on the rod's bending stiffness a section's disks give.
BENDING_SCALE_RANGE = (0.1, 100.0)
_TOP_KEYS = {'name', 'description', 'rod', 'base', 'gravity', 'cables', 'guides', 'solver',
             'sections', 'cable_model', 'tendons', 'tip_marker', 'sensors', 'model_uncertainty',
             'dynamics', 'obstacles', 'clearance', 'body_radius', 'load_model', 'load_direction',
             'load_prior', 'tension_noise'}
#: The load models a robot file may name (``load_model``): the tip load in the fused state.
LOAD_MODELS = ('weight', 'direction', 'force', 'wrench')


def _frozen(array):
    array = np.array(array, dtype=float)
    array.setflags(write=False)
    return array


def _number(value, field):
    if isinstance(value, str):
        # PyYAML (YAML 1.1) reads 54.0e9 as a string: it wants a signed exponent, 54.0e+9
        try:
            value = float(value)
        except ValueError:
            raise ValueError('%s must be a number, got %r' % (field, value)) from None
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError('%s must be a number, got %r' % (field, value))
    if not math.isfinite(value):
        raise ValueError('%s must be finite, got %r' % (field, value))
    return float(value)


def _positive(value, field):
    value = _number(value, field)
    if value <= 0.0:
        raise ValueError('%s must be > 0, got %g' % (field, value))
    return value


def _vector(value, size, field):
    if not isinstance(value, (list, tuple)) or len(value) != size:
        raise ValueError('%s must be a list of %d numbers, got %r' % (field, size, value))
    return np.array([_number(x, '%s[%d]' % (field, i)) for i, x in enumerate(value)])


def _section(data, key, field):
    if key not in data:
        raise ValueError('missing key %s' % field)
    return data[key]


def _parse_rod(data):
    rod = mapping(_section(data, 'rod', 'rod'), 'rod', _ROD_KEYS)
    length = _positive(_section(rod, 'length', 'rod.length'), 'rod.length')
    diameter = _positive(_section(rod, 'diameter', 'rod.diameter'), 'rod.diameter')
    youngs = _positive(_section(rod, 'youngs_modulus', 'rod.youngs_modulus'),
                       'rod.youngs_modulus')
    density = _number(_section(rod, 'density', 'rod.density'), 'rod.density')
    if density < 0.0:
        raise ValueError('rod.density must be >= 0, got %g' % density)
    # beyond what any backbone material has, the model gives no usable shape (every
    # measurement would be rejected later without naming the cause)
    if not YOUNGS_RANGE[0] <= youngs <= YOUNGS_RANGE[1]:
        raise ValueError('rod.youngs_modulus must be in [%g, %g] Pa (soft polymers to steel '
                         'and beyond), got %g' % (*YOUNGS_RANGE, youngs))
    if density > MAX_DENSITY:
        raise ValueError('rod.density must be <= %g kg/m^3 (even with the disks lumped on the '
                         'backbone), got %g'
                         % (MAX_DENSITY, density))
    if 'shear_modulus' in rod and 'poisson_ratio' in rod:
        raise ValueError('rod: give either poisson_ratio or shear_modulus, not both')
    if 'shear_modulus' in rod:
        shear = _positive(rod['shear_modulus'], 'rod.shear_modulus')
    elif 'poisson_ratio' in rod:
        nu = _number(rod['poisson_ratio'], 'rod.poisson_ratio')
        if not -1.0 < nu <= 0.5:
            raise ValueError('rod.poisson_ratio must be in (-1, 0.5], got %g' % nu)
        shear = youngs / (2.0 * (1.0 + nu))
    else:
        raise ValueError('missing key rod.poisson_ratio (or rod.shear_modulus)')
    rigidities = {key: _positive(rod[key], 'rod.' + key)
                  for key in ('axial_rigidity', 'shear_rigidity') if key in rod}
    damping = mapping(rod.get('damping') or {}, 'rod.damping', _DAMPING_KEYS)
    for key in sorted(damping):
        value = _number(damping[key], 'rod.damping.' + key)
        if value < 0.0:
            raise ValueError('rod.damping.%s must be >= 0, got %g' % (key, value))
        rigidities[key + '_damping'] = value
    return Rod(length, diameter, youngs, shear, density, **rigidities)


def _parse_base(data):
    base = mapping(_section(data, 'base', 'base'), 'base', _BASE_KEYS)
    frame_id = _section(base, 'frame_id', 'base.frame_id')
    if not isinstance(frame_id, str) or not frame_id:
        raise ValueError('base.frame_id must be a non-empty string, got %r' % (frame_id,))
    position = _vector(base.get('position', [0.0, 0.0, 0.0]), 3, 'base.position')
    orientation = _vector(_section(base, 'orientation', 'base.orientation'), 4,
                          'base.orientation')
    norm = np.linalg.norm(orientation)
    if abs(norm - 1.0) > 1e-6:
        raise ValueError('base.orientation must be a unit quaternion [x, y, z, w], its norm is %g'
                         % norm)
    return frame_id, position, orientation / norm


def _parse_guides(data, length, prefix='', start=0.0):
    guides = data.get('guides') or []
    if not isinstance(guides, (list, tuple)):
        raise ValueError('%sguides must be a list of arc lengths in m, got %r' % (prefix, guides))
    guides = np.array([_number(g, '%sguides[%d]' % (prefix, i)) for i, g in enumerate(guides)])
    for i, g in enumerate(guides):
        if not 0.0 <= g <= length:
            raise ValueError('%sguides[%d] = %g is outside [0, rod.length = %g]'
                             % (prefix, i, g, length))
    if np.any(np.diff(guides) <= 0.0):
        raise ValueError('%sguides must be strictly increasing, got %s'
                         % (prefix, guides.tolist()))
    if len(guides) and guides[0] <= start and start > 0.0:
        raise ValueError('%sguides must start after the previous section ends at s = %g m, got '
                         '%g (sections go base to tip)' % (prefix, start, guides[0]))
    return guides


def _hole(value, field):
    """One hole offset [x, y] or [x, y, 0] (m) in the plane of its disk, off the axis."""
    if isinstance(value, (list, tuple)) and len(value) == 2:
        value = list(value) + [0.0]
    offset = _vector(value, 3, field)
    if abs(offset[2]) > 1e-9:
        raise ValueError('%s z must be 0: the hole lies in the plane of its disk '
                         '(the disks are placed by guides), got %g m' % (field, offset[2]))
    if np.hypot(offset[0], offset[1]) <= 0.0:
        raise ValueError('%s must be off the backbone axis (x or y non-zero), got %s'
                         % (field, offset.tolist()))
    return offset


def _check_helix_sampling(helix, path_guides, field):
    """Refuse a helix with half a turn or more between two disks of its path.

    The cable runs straight hole to hole: beyond half a turn per disk spacing the holes are
    those of a slower helix (one turn per spacing: a straight cable), the sampling limit.
    """
    spacing = float(np.max(np.diff(np.concatenate([[0.0], path_guides])), initial=0.0))
    turns = abs(helix.turns_per_metre) * spacing
    if turns >= 0.5:
        raise ValueError('%s.helix.turns_per_metre = %g is more than the disks can carry: %.2f '
                         'turn between disks %.1f mm apart, its holes alias another route '
                         '(fewer than %.3g turns/m: under half a turn per spacing)'
                         % (field, helix.turns_per_metre, turns, spacing * 1e3,
                            0.5 / spacing))


def _parse_route(cable, field, path_guides):
    """Return a cable's route and its hole at the end disk: ``offset``, ``offsets`` or ``helix``.

    ``path_guides``: arc lengths of the guides the cable passes, its end disk last (m).
    :returns: (route or None for a constant offset, end offset (3,))
    """
    given = [key for key in _ROUTE_KEYS if key in cable]
    if not given:
        raise ValueError('missing key %s.offset (or %s.offsets, one [x, y] per disk, or %s.helix '
                         '{radius, start_angle, turns_per_metre})' % (field, field, field))
    if len(given) > 1:
        raise ValueError('%s: give one of offset, offsets or helix, got %s' % (field, given))
    if 'offset' in cable:
        return None, _hole(cable['offset'], field + '.offset')
    end = float(path_guides[-1]) if len(path_guides) else 0.0
    if 'helix' in cable:
        helix = mapping(cable['helix'], field + '.helix', _HELIX_KEYS)
        route = Helix(
            radius=_positive(_section(helix, 'radius', field + '.helix.radius'),
                             field + '.helix.radius'),
            start_angle=_number(helix.get('start_angle', 0.0), field + '.helix.start_angle'),
            turns_per_metre=_number(_section(helix, 'turns_per_metre',
                                             field + '.helix.turns_per_metre'),
                                    field + '.helix.turns_per_metre'))
        _check_helix_sampling(route, path_guides, field)
        return route, route.at([end])[0][0]
    holes = cable['offsets']
    disks = np.concatenate([[0.0], path_guides])
    if not isinstance(holes, (list, tuple)) or len(holes) not in (len(path_guides), len(disks)):
        raise ValueError('%s.offsets must list one [x, y] (m) per guide disk of the cable, %d up '
                         "to its end disk (its hole in the base disk is then the first one's), "
                         "or %d with the base disk's (s = 0) first; got %r"
                         % (field, len(path_guides), len(disks), holes))
    holes = np.array([_hole(h, '%s.offsets[%d]' % (field, i)) for i, h in enumerate(holes)])
    if len(holes) == len(path_guides):  # straight from the base disk to the first guide
        holes = np.concatenate([holes[:1], holes])
    return GuideOffsets(_frozen(disks), _frozen(holes)), holes[-1]


def _parse_cables(data, guides, prefix='', names=None, tendons=None, defaults=None, routes=None,
                  path_guides=None):
    """Return the offsets (at the end disks) and length limits of one section's cables.

    Appends each cable's route to ``routes`` (``path_guides``: every guide up to this section's
    end disk, m).
    """
    cables = data.get('cables') or []
    path_guides = guides if path_guides is None else path_guides
    path_guides = path_guides[path_guides > 0.0]  # a guide at s = 0 is the base disk
    routes = [] if routes is None else routes
    if not isinstance(cables, (list, tuple)):
        raise ValueError('%scables must be a list of {name, offset}, got %r' % (prefix, cables))
    names = [] if names is None else names
    offsets, limits = [], []
    for i, cable in enumerate(cables):
        field = '%scables[%d]' % (prefix, i)
        cable = mapping(cable, field, _CABLE_KEYS)
        name = _section(cable, 'name', field + '.name')
        if not isinstance(name, str) or not name:
            raise ValueError('%s.name must be a non-empty string, got %r' % (field, name))
        if name in names:
            raise ValueError('%s.name: duplicate cable name %r' % (field, name))
        route, offset = _parse_route(cable, field, path_guides)
        routes.append(route)
        if 'length_limits' in cable:
            lim = _vector(cable['length_limits'], 2, field + '.length_limits')
        else:
            lim = np.array([0.0, math.inf])
        if not 0.0 <= lim[0] < lim[1]:
            raise ValueError('%s.length_limits must satisfy 0 <= min < max, got %s'
                             % (field, lim.tolist()))
        names.append(name)
        offsets.append(offset)
        limits.append(lim)
        if tendons is not None:
            tendons.append(_parse_tendon(cable, defaults or {}, field))
    if offsets and not np.any(guides > 0.0):
        raise ValueError('%scables need at least one guide at s > 0 (guides is empty)' % prefix)
    return np.reshape(offsets, (-1, 3)), np.reshape(limits, (-1, 2))


def _parse_sections(data, length, tendons, defaults, routes):
    """Sections from ``sections:`` or from today's top-level ``cables:`` + ``guides:``.

    Appends each cable's tendon parameters to ``tendons`` (``defaults``: the top-level block)
    and its route to ``routes``.
    """
    if 'sections' not in data:
        guides = _parse_guides(data, length)
        names = []
        offsets, limits = _parse_cables(data, guides, names=names, tendons=tendons,
                                        defaults=defaults, routes=routes)
        section = Section('section_0', _frozen(guides), tuple(range(len(names))))
        return (section,) if len(guides) or names else (), names, offsets, limits
    if 'cables' in data or 'guides' in data:
        raise ValueError('give either sections or top-level cables/guides, not both')
    raw = data['sections']
    if not isinstance(raw, (list, tuple)) or not raw:
        raise ValueError('sections must be a non-empty list of {name, guides, cables}')
    sections, names, offsets, limits, end = [], [], [], [], 0.0
    for k, item in enumerate(raw):
        prefix = 'sections[%d].' % k
        item = mapping(item, 'sections[%d]' % k, _SECTION_KEYS)
        name = item.get('name', 'section_%d' % k)
        if not isinstance(name, str) or not name:
            raise ValueError('%sname must be a non-empty string, got %r' % (prefix, name))
        if name in [section.name for section in sections]:
            raise ValueError('%sname: duplicate section name %r' % (prefix, name))
        guides = _parse_guides(item, length, prefix, end)
        if not len(guides) or guides[-1] <= 0.0:
            raise ValueError('%sguides must list at least one guide disk at s > 0 (its end disk)'
                             % prefix)
        first = len(names)
        section_defaults = dict(defaults)
        section_defaults.update(_tendon_block(item.get('tendons'), prefix + 'tendons'))
        path_guides = np.concatenate([s.guides for s in sections] + [guides])
        section_offsets, section_limits = _parse_cables(item, guides, prefix, names, tendons,
                                                        section_defaults, routes, path_guides)
        scale = _positive(item.get('bending_scale', 1.0), prefix + 'bending_scale')
        if not BENDING_SCALE_RANGE[0] <= scale <= BENDING_SCALE_RANGE[1]:
            raise ValueError("%sbending_scale must be in [%g, %g] (a factor on the rod's E I "
                             'and G J over the section), got %g'
                             % (prefix, *BENDING_SCALE_RANGE, scale))
        disk_mass = _number(item.get('disk_mass', 0.0), prefix + 'disk_mass')
        if not 0.0 <= disk_mass <= MAX_DISK_MASS:
            raise ValueError('%sdisk_mass must be in [0, %g] kg (the mass of each guide disk), '
                             'got %g' % (prefix, MAX_DISK_MASS, disk_mass))
        sections.append(Section(name, _frozen(guides), tuple(range(first, len(names))), scale,
                                disk_mass))
        offsets.append(section_offsets)
        limits.append(section_limits)
        end = guides[-1]
    return (tuple(sections), names, np.concatenate(offsets), np.concatenate(limits))


def _plausibility(rod, offsets, sections):
    """Warnings for values a real robot would not have (the model still runs)."""
    warnings = []
    if rod.diameter > 0.1 * rod.length:
        warnings.append('rod.diameter %g m is over a tenth of rod.length %g m: not a slender rod'
                        % (rod.diameter, rod.length))
    nested = len(sections) > 1 or (sections and sections[0].name != 'section_0')
    for k, section in enumerate(sections):
        for i, j in enumerate(section.cable_indices):
            field = ('sections[%d].cables[%d].offset' % (k, i) if nested
                     else 'cables[%d].offset' % j)
            radius = float(np.hypot(*offsets[j, :2]))
            if not rod.diameter / 2.0 <= radius <= 0.25 * rod.length:
                warnings.append('%s: hole radius %g m is outside [rod radius %g m, rod.length '
                                '/ 4 = %g m]' % (field, radius, rod.diameter / 2.0,
                                                 0.25 * rod.length))
    return tuple(warnings)


def _tendon_block(block, field):
    """Return the validated tendon defaults of a ``tendons:`` mapping (empty when absent)."""
    if block is None:
        return {}
    block = mapping(block, field, set(TENDON_KEYS))
    return {key: _tendon_value(key, value, '%s.%s' % (field, key))
            for key, value in block.items()}


def _tendon_value(key, value, field):
    """Return one tendon parameter, checked.

    stiffness > 0 (N), pretension >= 0 (N), friction >= 0, tension_limits 0 <= min < max (N),
    stick_length >= 0 (m), zero_offset (m).
    """
    if key == 'stiffness':
        return _positive(value, field)
    if key == 'tension_limits':
        lim = _vector(value, 2, field)
        if not 0.0 <= lim[0] < lim[1]:
            raise ValueError('%s must satisfy 0 <= min < max (N), got %s' % (field, lim.tolist()))
        return lim
    value = _number(value, field)
    if key in ('pretension', 'friction', 'stick_length') and value < 0.0:
        raise ValueError('%s must be >= 0, got %g' % (field, value))
    return value


def _parse_tendon(cable, defaults, field):
    """Return a cable's tendon parameters: its own keys over its section's and file's defaults."""
    values = dict(defaults)
    for key in TENDON_KEYS + ('zero_offset',):
        if key in cable:
            values[key] = _tendon_value(key, cable[key], '%s.%s' % (field, key))
    return values


def _tendons(rows):
    """Return the :class:`Tendons` of every cable (defaults for what no file entry gives)."""
    tendons = Tendons.default(len(rows))
    arrays = {name: np.array(getattr(tendons, name)) for name in tendons.__dataclass_fields__}
    for j, values in enumerate(rows):
        for key, value in values.items():
            arrays[key][j] = value
    return Tendons(**{key: _frozen(value) for key, value in arrays.items()})


#: Tendon plausibility (robot file errors, not warnings: the model would run and mislead).
#: EA of a steel bar 25 cm across, N: anything stiffer is an inextensible cable (give no
#: stiffness; the inextensible-limit tests use 1e9).
MAX_TENDON_STIFFNESS = 1e10
#: EA below this, N, or below the upper tension limit (the cable would double its length
#: there) is no cable a robot pulls with.
MIN_TENDON_STIFFNESS = 1.0
#: |zero_offset| above this fraction of the rod length is a homing error, not an offset.
MAX_ZERO_OFFSET_FRACTION = 0.1


def _check_tendons(rows, names, rod_length):
    """ValueError for tendon values that contradict each other or the rod, naming the cable."""
    for name, values in zip(names, rows):
        field = 'cable %r' % name
        limits = values.get('tension_limits', (0.0, math.inf))
        stiffness = values.get('stiffness')
        if stiffness is not None:
            low = max(MIN_TENDON_STIFFNESS, limits[1] if math.isfinite(limits[1]) else 0.0)
            if not low <= stiffness <= MAX_TENDON_STIFFNESS:
                raise ValueError('%s: tendons stiffness (EA) %g N is outside [%g, %g] N: below it '
                                 'the cable would double its length at its tension limit, above '
                                 'it give no stiffness (an inextensible cable)'
                                 % (field, stiffness, low, MAX_TENDON_STIFFNESS))
        pretension = values.get('pretension', 0.0)
        if not limits[0] <= pretension <= limits[1]:
            raise ValueError('%s: tendons pretension %g N is outside tension_limits [%g, %g] N '
                             '(every solve would report it over a limit)'
                             % (field, pretension, limits[0], limits[1]))
        offset = values.get('zero_offset', 0.0)
        if abs(offset) > MAX_ZERO_OFFSET_FRACTION * rod_length:
            raise ValueError('%s: zero_offset %g m is more than %g of the %g m rod: a homing '
                             'error, not an offset (re-home the cable, or calibrate --fit '
                             'cable_zero)' % (field, offset, MAX_ZERO_OFFSET_FRACTION,
                                              rod_length))


def _tendon_warnings(rows, names):
    """Warnings for tendon values no real robot has (the model still runs)."""
    warnings = []
    for name, values in zip(names, rows):
        if values.get('friction', 0.0) > 1.0:
            warnings.append('cable %r: friction %g is above 1 (steel on steel is ~0.2)'
                            % (name, values['friction']))
        if values.get('pretension', 0.0) > 0.0 and 'stiffness' not in values:
            warnings.append("cable %r: pretension without stiffness: an inextensible cable's "
                            'tension does not follow from its length' % name)
    return tuple(warnings)


def _parse_solver(data):
    solver = data.get('solver') or {}
    defaults = SolverSettings()
    solver = mapping(solver, 'solver', set(defaults.__dataclass_fields__))
    steps = solver.get('steps', defaults.steps)
    if isinstance(steps, bool) or not isinstance(steps, int) or not 1 <= steps <= MAX_STEPS:
        raise ValueError('solver.steps must be an integer in [1, %d] (the default 40 is within '
                         '1e-5 m of converged; more only slows every solve), got %r'
                         % (MAX_STEPS, steps))
    iterations = solver.get('max_iterations', defaults.max_iterations)
    if isinstance(iterations, bool) or not isinstance(iterations, int) or iterations < 1:
        raise ValueError('solver.max_iterations must be an integer >= 1, got %r' % (iterations,))
    tolerances = {key: _positive(solver.get(key, getattr(defaults, key)), 'solver.' + key)
                  for key in ('bvp_tolerance', 'estimate_tolerance', 'goal_tolerance')}
    return SolverSettings(steps=steps, max_iterations=iterations, **tolerances)


def parse_robot_description(data, source='robot file'):
    """Validate the mapping of a robot file and return a :class:`RobotDescription`."""
    if not isinstance(data, dict):
        raise ValueError('%s must be a YAML mapping at the top level' % source)
    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        raise ValueError('%s has unknown top-level keys %s (allowed: %s)'
                         % (source, unknown, ', '.join(sorted(_TOP_KEYS))))
    rod = _parse_rod(data)
    frame_id, position, orientation = _parse_base(data)
    gravity = _vector(_section(data, 'gravity', 'gravity'), 3, 'gravity')
    defaults = _tendon_block(data.get('tendons'), 'tendons')
    tendon_rows, routes = [], []
    sections, names, offsets, limits = _parse_sections(data, rod.length, tendon_rows, defaults,
                                                       routes)
    _check_tendons(tendon_rows, names, rod.length)
    model = data.get('cable_model', 'point_moment')
    if model not in CABLE_MODELS:
        raise ValueError('cable_model must be one of %s, got %r'
                         % (', '.join(CABLE_MODELS), model))
    guides = np.concatenate([section.guides for section in sections]) if sections else []
    tip_marker = _vector(data.get('tip_marker', [0.0, 0.0, 0.0]), 3, 'tip_marker')
    return RobotDescription(
        name=str(data.get('name', 'continuum_robot')), rod=rod, base_frame_id=frame_id,
        base_position=_frozen(position), base_orientation=_frozen(orientation),
        gravity=_frozen(gravity), cable_names=tuple(names), cable_offsets=_frozen(offsets),
        cable_length_limits=_frozen(limits), guides=_frozen(guides),
        solver=_parse_solver(data), sections=sections, cable_model=model,
        warnings=_plausibility(rod, offsets, sections) + _tendon_warnings(tendon_rows, names),
        tendons=_tendons(tendon_rows),
        cable_routes=tuple(routes) if any(route is not None for route in routes) else (),
        tip_marker=_frozen(tip_marker),
        sensors=parse_sensors(data.get('sensors'), rod.length, guides, tip_marker),
        model_uncertainty=parse_model_uncertainty(data.get('model_uncertainty')),
        dynamics=_parse_dynamics(data), obstacles=parse_obstacles(data.get('obstacles')),
        clearance=_clearance(data.get('clearance', 0.0), 'clearance'),
        body_radius=(None if data.get('body_radius') is None
                     else _positive(data['body_radius'], 'body_radius')),
        load=_parse_load(data), tension_noise=_tension_noise(data.get('tension_noise')))


def _tension_noise(value):
    """Return a measured tension's sigma: N (> 0) or 'P%' of each reading; None when absent."""
    if value is None:
        return None
    if isinstance(value, str) and value.strip().endswith('%'):
        percent = _positive(value.strip()[:-1], 'tension_noise (percent)')
        return '%g%%' % percent
    return _positive(value, 'tension_noise')


def _parse_load(data):
    """Return (model, direction or None, prior or None) of ``load_model``, or None without it.

    The model's own checks (gravity for 'weight', a prior's size) run when the robot is built.
    """
    name = data.get('load_model')
    if name is None:
        extra = [key for key in ('load_direction', 'load_prior') if key in data]
        if extra:
            raise ValueError('%s given without load_model (%s)'
                             % (' and '.join(extra), ' | '.join(LOAD_MODELS)))
        return None
    if name not in LOAD_MODELS:
        raise ValueError('load_model must be one of %s, got %r' % (' | '.join(LOAD_MODELS), name))
    direction = data.get('load_direction')
    if (direction is None) != (name != 'direction'):
        raise ValueError("load_direction goes with load_model 'direction' (and only with it)")
    if direction is not None:
        direction = tuple(_vector(direction, 3, 'load_direction'))
    prior = data.get('load_prior')
    if prior is not None:
        values = prior if isinstance(prior, (list, tuple)) else [prior]
        prior = tuple(_positive(value, 'load_prior[%d]' % i) for i, value in enumerate(values))
    return name, direction, prior


def _clearance(value, field):
    """Check a clearance (m): >= 0 and under 1 m (mm given as m is the usual mistake)."""
    value = _number(value, field)
    if not 0.0 <= value < 1.0:
        raise ValueError('%s must be in [0, 1) m, got %g' % (field, value))
    return value


def _parse_dynamics(data):
    defaults = DynamicsSettings()
    section = mapping(data.get('dynamics') or {}, 'dynamics', {'dt', 'alpha'})
    return DynamicsSettings(*check_dynamics(section.get('dt', defaults.dt),
                                            section.get('alpha', defaults.alpha)))


def read_robot_description(path):
    """Read and validate a robot file (YAML)."""
    try:
        with open(path, 'r', encoding='utf-8') as stream:
            data = yaml.safe_load(stream)
    except OSError as error:
        raise ValueError('cannot read robot file %s: %s' % (path, error)) from error
    except yaml.YAMLError as error:
        raise ValueError('robot file %s is not valid YAML: %s' % (path, error)) from error
    return parse_robot_description(data, source=str(path))
