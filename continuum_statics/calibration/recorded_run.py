"""Recorded runs: time-ordered cable lengths and measured tip positions, in SI units.

A recorded run is what ``calibrate`` fits a robot model to. Two sources are read:

- a CSV file, one row per sample. The project's own layout is a ``timestamp`` column (s), one
  column per cable name with its length as ``cable_states`` reports it (m) and ``tip_x, tip_y,
  tip_z`` (m). Other labs' files are read through a :class:`ColumnMap`: which column is which
  cable, whether it holds a length or a motor-side displacement, and the units. Lines starting
  with ``#`` are comments. Other sensors of the robot file (an EM coil on the body) may have
  columns ``<name>_x, <name>_y, <name>_z`` in the tips' units and frame, empty where they gave
  nothing: ``calibrate --model-uncertainty`` measures the model's error at their points too.
- a rosbag2 recording (directory or ``.mcap`` file): ``.../cable_states`` (JointState, lengths
  in m) and a measured tip topic (PoseStamped, m). Each tip message is one sample, paired with
  the latest cable_states at or before it. Another sensor's ``.../sensors/<name>``
  (PoseStamped or PoseWithCovarianceStamped) gives a sample its point when one of its messages
  is stamped within :data:`PAIRING_WINDOW` of the tip's; a sensor in another frame than the
  tips is left out (``notes`` says so).

Lengths come out in the robot's cable order, in m; tips in m, in the tracker's frame.
"""
import csv
from dataclasses import dataclass, field
import math
from pathlib import Path

import numpy as np

from continuum_statics.calibration.bag_reading import open_bag, pick_connections

KINDS = ('length', 'displacement')
#: s: a bag's sensor message pairs with the tip sample stamped nearest to it, this close (a
#: 40 Hz EM coil beside a 120 Hz tracker: within 12.5 ms)
PAIRING_WINDOW = 0.02
_SENSOR_TYPES = ('geometry_msgs/msg/PoseStamped', 'geometry_msgs/msg/PoseWithCovarianceStamped')


@dataclass(frozen=True)
class ColumnMap:
    """Which CSV columns hold what, and how to turn them into SI values.

    With ``kind='displacement'`` the length of cable j is
    ``straight_j - sign * scale * value_j``, straight_j being its length (m) at the homed
    straight pose.
    """

    cables: tuple = ()          # one column per cable, cable_names order; () = named as cables
    kind: str = 'length'        # 'length' (m after scale) or 'displacement' (motor-side travel)
    sign: float = 1.0           # displacement: +1 = a positive value shortens (pulls) the cable
    scale: float = 1.0          # cable columns * scale = m (0.001 for mm)
    tips: tuple = ('tip_x', 'tip_y', 'tip_z')
    tip_scale: float = 1.0      # tip columns * tip_scale = m
    time: str = 'timestamp'     # optional (s): without it rows are numbered 0, 1, 2 ... s
    label: str = 'pattern_label'  # optional text column kept per row

    def __post_init__(self):
        # lists from callers become tuples: the map stays hashable and immutable
        object.__setattr__(self, 'cables', tuple(self.cables))
        object.__setattr__(self, 'tips', tuple(self.tips))
        if self.kind not in KINDS:
            raise ValueError('cable kind %r: expected one of %s' % (self.kind, ', '.join(KINDS)))
        if self.sign not in (1.0, -1.0):
            raise ValueError('cable sign %r: expected 1 or -1' % (self.sign,))
        for name in ('scale', 'tip_scale'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value != 0.0):
                raise ValueError('%s %r: expected a finite non-zero factor' % (name, value))
        if len(self.tips) != 3:
            raise ValueError('tip columns %s: expected three (x, y, z)' % ','.join(self.tips))


def _names(text):
    return tuple(name.strip() for name in text.split(',') if name.strip())


def add_column_arguments(parser):
    """Add the options that build a :class:`ColumnMap` (see :func:`column_map_from_args`)."""
    parser.add_argument(
        '--cable-columns', default='', metavar='COL,COL,...',
        help="CSV columns of the cables, one per robot cable in the robot file's cable order "
             '(default: columns named as the cables), e.g. for the FTDCR v6 data '
             'servo_1_mm,servo_20_mm,servo_23_mm,servo_9_mm,servo_6_mm,servo_11_mm,'
             'servo_24_mm,servo_2_mm,servo_3_mm')
    parser.add_argument(
        '--cable-kind', choices=KINDS, default='length',
        help='what the cable columns hold: "length" (the cable length, m after --cable-scale; '
             'default) or "displacement" (motor-side travel from the homed straight pose, '
             'e.g. FTDCR v6: displacement)')
    parser.add_argument(
        '--cable-sign', type=float, choices=(1.0, -1.0), default=1.0,
        help='displacement only: 1 if a positive value pulls (shortens) the cable, -1 if it '
             'pays it out (default 1; FTDCR v6: 1)')
    parser.add_argument(
        '--cable-scale', type=float, default=1.0,
        help="factor from the cable columns' unit to m (default 1; mm: 0.001, as FTDCR v6)")
    parser.add_argument(
        '--tip-columns', default='tip_x,tip_y,tip_z', metavar='X,Y,Z',
        help='CSV columns of the measured tip position (default tip_x,tip_y,tip_z)')
    parser.add_argument(
        '--tip-scale', type=float, default=1.0,
        help="factor from the tip columns' unit to m (default 1; mm: 0.001, as FTDCR v6)")


def column_map_from_args(args):
    """Return the :class:`ColumnMap` of options added by :func:`add_column_arguments`.

    :raises ValueError: on inconsistent options (e.g. not three tip columns)
    """
    return ColumnMap(cables=_names(args.cable_columns), kind=args.cable_kind,
                     sign=args.cable_sign, scale=args.cable_scale,
                     tips=_names(args.tip_columns), tip_scale=args.tip_scale)


@dataclass(frozen=True)
class RecordedRun:
    """Samples of a run in time order (SI units)."""

    times: np.ndarray    # (n,) s
    labels: tuple        # (n,) str ('' when absent)
    lengths: np.ndarray  # (n, n_cables) m, robot cable order, motor-side as cable_states has them
    tips: np.ndarray     # (n, 3) m, tracker frame
    source: str          # file path
    #: {sensor name: (n, 3) m} other sensors' points, tracker frame (NaN: none on that row)
    points: dict = field(default_factory=dict)
    notes: tuple = ()    # what the reader left out, and why

    def __len__(self):
        return len(self.times)

    def subset(self, mask_or_indices):
        """Return the run of the samples a boolean mask or an index array selects."""
        index = np.asarray(mask_or_indices)
        if index.dtype == bool and index.shape != self.times.shape:
            raise ValueError('mask of %d values for a run of %d samples'
                             % (index.size, len(self)))
        return RecordedRun(times=self.times[index],
                           labels=tuple(np.array(self.labels, dtype=object)[index]),
                           lengths=self.lengths[index], tips=self.tips[index],
                           source=self.source,
                           points={name: p[index] for name, p in self.points.items()},
                           notes=self.notes)


def read_recorded_run(path, cable_names, straight_lengths, column_map=ColumnMap(),
                      tip_topic='tip_pose_measured', sensor_names=()):
    """Read a recorded run from a CSV file or a rosbag2 recording (directory or ``.mcap``).

    :param cable_names: the robot's cable names (the order of ``lengths`` columns)
    :param straight_lengths: each cable's length (m) at the homed straight pose
        (``robot.straight_cable_lengths``); used by displacement columns
    :param column_map: CSV columns (ignored for a bag)
    :param tip_topic: bag topic (or its last name parts) of the measured tip PoseStamped
    :param sensor_names: other sensors whose points the run may hold, read into ``points``: a
        CSV's columns ``<name>_x, <name>_y, <name>_z`` (the tips' scale and frame; an empty or
        ``nan`` cell: none on that row), a bag's ``.../sensors/<name>`` topic
    :raises ValueError: naming the file, and the row and column, of what cannot be read
    """
    path = Path(path)
    cable_names = list(cable_names)
    if path.is_dir() or path.suffix == '.mcap':
        return _read_bag(path, cable_names, tip_topic, sensor_names)
    return _read_csv(path, cable_names, straight_lengths, column_map, sensor_names)


def check_tip_units(tips, rod_length, source, option='--tip-scale 0.001'):
    """ValueError when tips (m) spread further than one rod can reach: tips in mm, most likely.

    Every tip of one robot lies within a rod length of its base, so no tip is further than
    2 L from the median tip, whatever the tracker's frame.
    """
    tips = np.asarray(tips, dtype=float).reshape(-1, 3)
    spread = float(np.max(np.linalg.norm(tips - np.median(tips, axis=0), axis=1)))
    if spread > 2.0 * rod_length:
        raise ValueError('%s: the tips spread over %.4g m, but a %.3g m rod reaches at most '
                         '%.3g m from its base: are the tips in mm? (%s converts them)'
                         % (source, spread, rod_length, rod_length, option))


def _read_csv(path, cable_names, straight_lengths, columns, sensor_names=()):
    cable_columns = list(columns.cables or cable_names)
    if len(cable_columns) != len(cable_names):
        raise ValueError('%d cable columns (%s) for a robot of %d cables (%s)' % (
            len(cable_columns), ','.join(cable_columns), len(cable_names),
            ','.join(cable_names)))
    if columns.kind == 'displacement':
        straight = np.asarray(straight_lengths, dtype=float).reshape(-1)
        if straight.shape != (len(cable_names),):
            raise ValueError('%d straight lengths for %d cables'
                             % (straight.size, len(cable_names)))
    try:
        with open(path, newline='', encoding='utf-8') as stream:
            # keep file line numbers so that errors point at the line to fix
            lines = [(number, line) for number, line in enumerate(stream, start=1)
                     if line.strip() and not line.lstrip().startswith('#')]
    except (OSError, UnicodeDecodeError) as error:
        raise ValueError('cannot read %s: %s' % (path, error)) from None
    if not lines:
        raise ValueError('%s is empty' % path)
    header = [name.strip() for name in next(csv.reader([lines[0][1]]))]
    doubled = sorted({name for name in header if header.count(name) > 1})
    if doubled:
        raise ValueError('%s: column %s appears more than once' % (path, ', '.join(doubled)))
    missing = [c for c in cable_columns + list(columns.tips) if c not in header]
    if missing:
        raise ValueError('%s lacks the column(s) %s (header: %s)'
                         % (path, ', '.join(missing), ','.join(header)))
    numeric = cable_columns + list(columns.tips)
    has_time = columns.time in header
    if has_time:
        numeric.append(columns.time)
    at = [header.index(c) for c in numeric]
    label_at = header.index(columns.label) if columns.label in header else None
    sensor_at = {}
    for name in sensor_names:
        present = ['%s_%s' % (name, axis) in header for axis in 'xyz']
        if any(present) and not all(present):
            raise ValueError('%s has %s but not %s: a sensor point needs all three' % (
                path, ', '.join(name + '_' + a for a, p in zip('xyz', present) if p),
                ', '.join(name + '_' + a for a, p in zip('xyz', present) if not p)))
        if all(present):
            sensor_at[name] = [header.index('%s_%s' % (name, axis)) for axis in 'xyz']
    values, labels, points = [], [], []
    for row_number, (line_number, line) in enumerate(lines[1:], start=1):
        where = '%s, row %d (line %d)' % (path, row_number, line_number)
        cells = next(csv.reader([line]))
        if len(cells) != len(header):
            raise ValueError('%s: %d cells, the header has %d'
                             % (where, len(cells), len(header)))
        row = []
        for name, i in zip(numeric, at):
            try:
                value = float(cells[i])
            except ValueError:
                raise ValueError('%s, column %s: %r is not a number'
                                 % (where, name, cells[i])) from None
            if not math.isfinite(value):
                raise ValueError('%s, column %s: %r is not finite' % (where, name, cells[i]))
            row.append(value)
        values.append(row)
        points.append([_optional(cells[i], where, header[i]) for at in sensor_at.values()
                       for i in at])
        labels.append(cells[label_at].strip() if label_at is not None else '')
        if has_time and len(values) > 1 and row[-1] < values[-2][-1]:
            raise ValueError("%s, column %s: time %r is before the previous row's %r "
                             '(rows must be in time order)'
                             % (where, columns.time, row[-1], values[-2][-1]))
    if not values:
        raise ValueError('%s has a header but no data rows' % path)
    table = np.array(values, dtype=float)
    n = len(cable_names)
    cables = table[:, :n] * columns.scale
    if columns.kind == 'displacement':
        cables = straight - columns.sign * cables
    return RecordedRun(
        times=table[:, -1] if has_time else np.arange(len(table), dtype=float),
        labels=tuple(labels), lengths=cables, tips=table[:, n:n + 3] * columns.tip_scale,
        source=str(path), points={name: np.array(points, dtype=float).reshape(len(table), -1)
                                  [:, 3 * j:3 * j + 3] * columns.tip_scale
                                  for j, name in enumerate(sensor_at)})


def _optional(cell, where, name):
    """Return a sensor cell's value: NaN when empty or ``nan`` (no reading on that row)."""
    try:
        value = float(cell) if cell.strip() else math.nan
    except ValueError:
        raise ValueError('%s, column %s: %r is not a number' % (where, name, cell)) from None
    if math.isinf(value):
        raise ValueError('%s, column %s: %r is not finite' % (where, name, cell))
    return value


def _stamp(msg, received):
    """Message time (ns): its header stamp when set, else the bag's receive time."""
    stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
    return stamp if stamp != 0 else received


def _read_bag(path, cable_names, tip_topic, sensor_names=()):
    reader = open_bag(path)
    try:
        connections = list(reader.connections)
        states = pick_connections(connections, 'cable_states', 'sensor_msgs/msg/JointState')
        # matched as plot.py does: the exact topic or its last name parts ('tip' ~ '/a/tip')
        tip = pick_connections(connections, tip_topic, 'geometry_msgs/msg/PoseStamped')
        topics = ', '.join(sorted('%s (%s)' % (c.topic, c.msgtype) for c in connections))
        if not states:
            raise ValueError('bag %s has no .../cable_states JointState topic (topics: %s)'
                             % (path, topics))
        if not tip:
            raise ValueError('bag %s has no .../%s PoseStamped topic (topics: %s)'
                             % (path, tip_topic, topics))
        tip_ids = {c.id for c in tip}
        sensors = {}  # connection id -> sensor name
        for name in sensor_names:
            for msgtype in _SENSOR_TYPES:
                sensors.update((c.id, name) for c in pick_connections(
                    connections, 'sensors/' + name, msgtype))
        seen = {name: ([], []) for name in set(sensors.values())}
        frames = {}  # topic kind ('tip' or a sensor name) -> the frame ids of its messages
        column = {name: j for j, name in enumerate(cable_names)}
        orders = {}  # JointState name tuple -> robot cable index of each entry
        state_times, state_lengths, tip_times, tip_points = [], [], [], []
        chosen = [c for c in connections if c.id in sensors]
        for connection, received, raw in reader.messages(connections=states + tip + chosen):
            msg = reader.deserialize(raw, connection.msgtype)
            t = _stamp(msg, received)
            if connection.id in tip_ids or connection.id in sensors:
                pose = msg.pose.pose if hasattr(msg.pose, 'pose') else msg.pose
                kind = sensors.get(connection.id, 'tip')
                frames.setdefault(kind, set()).add(msg.header.frame_id)
                times, points = (tip_times, tip_points) if kind == 'tip' else seen[kind]
                times.append(t)
                points.append((pose.position.x, pose.position.y, pose.position.z))
                continue
            names = tuple(msg.name)
            if names not in orders:
                orders[names] = _order(names, column, path, connection.topic)
            if len(msg.position) != len(names):
                raise ValueError('bag %s, %s at %.9f s: %d positions for %d names'
                                 % (path, connection.topic, t * 1e-9, len(msg.position),
                                    len(names)))
            lengths = np.empty(len(cable_names))
            lengths[orders[names]] = msg.position
            state_times.append(t)
            state_lengths.append(lengths)
    finally:
        reader.close()
    if not state_times:
        raise ValueError('bag %s: no cable_states messages' % path)
    # Header stamps need not arrive in order (tracker latency), so sort before pairing.
    state_order = np.argsort(state_times, kind='stable')
    state_times = np.asarray(state_times, dtype=np.int64)[state_order]
    state_lengths = np.asarray(state_lengths)[state_order]
    tip_order = np.argsort(tip_times, kind='stable')
    tip_times = np.asarray(tip_times, dtype=np.int64).reshape(-1)[tip_order]
    tip_points = np.asarray(tip_points, dtype=float).reshape(-1, 3)[tip_order]
    # latest cable_states at or before each tip; -1 = the tip came before any cable_states
    latest = np.searchsorted(state_times, tip_times, side='right') - 1
    # a tracker that loses the marker publishes NaN: such a sample carries no measurement
    keep = (latest >= 0) & np.all(np.isfinite(tip_points), axis=1)
    tip_frames = frames.get('tip', set()) - {''}
    notes = []
    for name in sorted(seen):
        # an empty frame id: the sender's default, taken as the tips'
        named = frames.get(name, set()) - {''}
        if named and named != tip_frames:
            notes.append('sensors/%s is in frame %s, the tips in %s: left out (its points are '
                         "read in the tips' frame)" % (name, ', '.join(sorted(named)),
                                                       ', '.join(sorted(tip_frames)) or '""'))
            del seen[name]
    return RecordedRun(times=tip_times[keep] * 1e-9, labels=('',) * int(keep.sum()),
                       lengths=state_lengths[latest[keep]], tips=tip_points[keep],
                       source=str(path), points={name: _paired(tip_times[keep], *seen[name])
                                                 for name in sorted(seen)}, notes=tuple(notes))


def _paired(sample_times, times, points):
    """Return (n, 3) m: each sample's nearest sensor point stamped within the window, else NaN.

    ``sample_times`` sorted (ns); ``times`` (ns) and ``points`` a sensor's messages, any order.
    """
    order = np.argsort(times, kind='stable')
    times = np.asarray(times, dtype=np.int64)[order]
    points = np.asarray(points, dtype=float).reshape(-1, 3)[order]
    out = np.full((len(sample_times), 3), np.nan)
    if not len(times):
        return out
    at = np.searchsorted(times, sample_times)
    before, after = np.maximum(at - 1, 0), np.minimum(at, len(times) - 1)
    nearest = np.where(np.abs(times[before] - sample_times)
                       <= np.abs(times[after] - sample_times), before, after)
    close = np.abs(times[nearest] - sample_times) <= PAIRING_WINDOW * 1e9
    out[close] = points[nearest[close]]
    return out


def _order(names, column, path, topic):
    """Robot cable index of each JointState entry; ``ValueError`` names unknown/missing ones."""
    unknown = [n for n in names if n not in column]
    missing = [n for n in column if n not in names]
    if unknown or missing or len(set(names)) != len(names):
        raise ValueError("bag %s, %s: cable names %s do not match the robot's %s%s%s"
                         % (path, topic, ','.join(names), ','.join(column),
                            '; unknown: ' + ', '.join(unknown) if unknown else '',
                            '; missing: ' + ', '.join(missing) if missing else ''))
    return np.array([column[n] for n in names])

