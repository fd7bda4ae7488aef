"""``python -m continuum_statics plot BAG``: PNG figures of a recording (matplotlib, Agg).

Reads a rosbag2 directory (ours or one from ``ros2 bag record``, MCAP or SQLite) or a single
``.mcap`` file with the ``rosbags`` library and writes, for what the bag contains:

- ``backbone.png``: the backbone at the end of each goal (the last one before the next goal
  started), or at several instants of a recording without goals, in 3-D (equal axes, base frame)
- ``tip_path.png``: tip path in 3-D with the goals, and each tip coordinate over time on an axis
  of its own, with the goal in force drawn as a step
- ``cable_lengths.png``: commanded vs measured cable lengths over time, one axis per cable in
  the robot file's order (the order the driver's and controller's JointStates list them)
- ``solver.png``: statics solve time and residual over time (from ``/diagnostics``)

Topics are found by name and type (``.../backbone`` Path, ``.../tip_pose`` PoseStamped,
``.../tip_goal_active`` (every goal the controller took, from any source; older bags:
``.../tip_goal_pose``), ``.../cable_commands``, ``.../cable_states``, ``/diagnostics``); a figure
whose topics are missing is skipped with a note.
"""
import argparse
from dataclasses import dataclass, field
import os
from pathlib import Path
import sys

import numpy as np

from continuum_statics.calibration.bag_reading import open_bag
from continuum_statics.calibration.bag_reading import pick_connections as pick

#: Backbone snapshots drawn in backbone.png.
SNAPSHOTS = 6
#: Most samples kept per time series (longer recordings are thinned evenly: bounded memory).
MAX_POINTS = 20000


@dataclass
class Recording:
    """What the figures need from a bag; times in s from the bag's start, lengths in m."""

    start_ns: int = 0
    frame_id: str = ''
    snapshots: list = field(default_factory=list)      # [(t, (N, 3) positions)]
    goal_snapshots: list = field(default_factory=list)  # [(t, (N, 3) positions)] at goal ends
    tip: list = field(default_factory=list)            # [(t, x, y, z)]
    goals: list = field(default_factory=list)          # [(t, x, y, z)]
    commanded: dict = field(default_factory=dict)      # name -> [(t, length)]
    measured: dict = field(default_factory=dict)       # name -> [(t, length)]
    solver: list = field(default_factory=list)         # [(t, median ms, max ms, residual m)]
    topics: dict = field(default_factory=dict)         # topic -> message type


def _point(p):
    return (p.x, p.y, p.z)


def _float(text):
    try:
        return float(text)
    except (TypeError, ValueError):
        return float('nan')


def read_recording(bag, snapshots=SNAPSHOTS):
    """Read the figures' data from ``bag`` (directory or .mcap); see :class:`Recording`.

    :raises ValueError: when the bag cannot be opened or read
    """
    reader = open_bag(bag)
    try:
        return _read(reader, snapshots)
    finally:
        reader.close()


def _read(reader, count):
    rec = Recording(start_ns=reader.start_time)
    connections = list(reader.connections)
    rec.topics = {c.topic: c.msgtype for c in connections}
    roles = {
        'backbone': pick(connections, 'backbone', 'nav_msgs/msg/Path'),
        'tip_pose': pick(connections, 'tip_pose', 'geometry_msgs/msg/PoseStamped'),
        'goal': (pick(connections, 'tip_goal_active', 'geometry_msgs/msg/PoseStamped')
                 or pick(connections, 'tip_goal_pose', 'geometry_msgs/msg/PoseStamped')),
        'commands': pick(connections, 'cable_commands', 'sensor_msgs/msg/JointState'),
        'states': pick(connections, 'cable_states', 'sensor_msgs/msg/JointState'),
        'diagnostics': pick(connections, 'diagnostics', 'diagnostic_msgs/msg/DiagnosticArray'),
    }
    role_of = {c.id: role for role, conns in roles.items() for c in conns}
    # Keep every stride-th message of a series (the counts are in the bag's index).
    stride = {role: max(1, -(-sum(c.msgcount for c in conns) // MAX_POINTS))
              for role, conns in roles.items()}
    stride['goal'] = 1  # every goal counts
    seen = dict.fromkeys(roles, -1)
    wanted = [c for conns in roles.values() for c in conns]
    duration = max(reader.end_time - 1 - reader.start_time, 1)  # end_time: last stamp + 1
    # Snapshot instants spread over the recording; the first backbone after each is kept.
    targets = [reader.start_time + duration * i // max(count - 1, 1) for i in range(count)]
    next_target = 0
    tip_from_backbone = not roles['tip_pose']
    last_goal = None
    last_backbone = None  # (t, connection, raw) of the newest backbone: the final snapshot
    for connection, stamp, raw in (reader.messages(connections=wanted) if wanted else ()):
        role = role_of[connection.id]
        t = (stamp - reader.start_time) * 1e-9
        seen[role] += 1
        sampled = seen[role] % stride[role] == 0
        if role == 'backbone':
            last_backbone = (t, connection, raw)
            take = next_target < len(targets) and stamp >= targets[next_target]
            if not (take or (tip_from_backbone and sampled)):
                continue
            msg = reader.deserialize(raw, connection.msgtype)
            if not msg.poses:
                continue
            rec.frame_id = rec.frame_id or msg.header.frame_id
            if take:
                positions = np.array([_point(p.pose.position) for p in msg.poses])
                rec.snapshots.append((t, positions))
                while next_target < len(targets) and stamp >= targets[next_target]:
                    next_target += 1
            if tip_from_backbone and sampled:
                rec.tip.append((t, *_point(msg.poses[-1].pose.position)))
        elif not sampled:
            continue
        elif role == 'tip_pose':
            msg = reader.deserialize(raw, connection.msgtype)
            rec.frame_id = rec.frame_id or msg.header.frame_id
            rec.tip.append((t, *_point(msg.pose.position)))
        elif role == 'goal':
            msg = reader.deserialize(raw, connection.msgtype)
            if rec.goals and last_backbone is not None:  # the backbone as the last goal ended
                _snapshot(reader, rec.goal_snapshots, last_backbone)
            last_goal = _point(msg.pose.position)
            rec.goals.append((t, *last_goal))
        elif role in ('commands', 'states'):
            msg = reader.deserialize(raw, connection.msgtype)
            series = rec.commanded if role == 'commands' else rec.measured
            for name, length in zip(msg.name, msg.position):
                series.setdefault(name, []).append((t, length))
        else:
            msg = reader.deserialize(raw, connection.msgtype)
            for status in msg.status:
                values = {kv.key: kv.value for kv in status.values}
                if 'solve_time_median_ms' in values:
                    rec.solver.append((t, _float(values['solve_time_median_ms']),
                                       _float(values.get('solve_time_max_ms')),
                                       _float(values.get('residual_m'))))
                if 'goal_m' in values:  # the tip controller's current goal (service goals)
                    goal = tuple(_float(v) for v in values['goal_m'].split()[:3])
                    # the same goal seen again (or first seen on tip_goal_pose) is one goal
                    if len(goal) == 3 and (last_goal is None or np.max(
                            np.abs(np.subtract(goal, last_goal))) > 1e-4):
                        rec.goals.append((t, *goal))
                        last_goal = goal
    if rec.goals and last_backbone is not None:
        _snapshot(reader, rec.goal_snapshots, last_backbone)
    if last_backbone is not None and len(rec.snapshots) < count and (
            not rec.snapshots or rec.snapshots[-1][0] < last_backbone[0]):
        t, connection, raw = last_backbone
        msg = reader.deserialize(raw, connection.msgtype)
        if msg.poses:
            rec.snapshots.append((t, np.array([_point(p.pose.position) for p in msg.poses])))
    return rec


# -- figures --------------------------------------------------------------------------------
def _pyplot():
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    return plt


def set_equal_3d(ax, points):
    """Equal scale on the three axes of ``ax`` around ``points`` (M, 3), m."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    points = points[np.all(np.isfinite(points), axis=1)]
    if points.size == 0:
        return
    low, high = points.min(axis=0), points.max(axis=0)
    centre = (low + high) / 2.0
    half = max(float(np.max(high - low)) / 2.0, 1e-3) * 1.05
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(centre[2] - half, centre[2] + half)
    ax.set_box_aspect((1.0, 1.0, 1.0))


def draw_base_frame(ax, size, frame_id):
    """Axes of the base frame at its origin: x red, y green, z blue (RViz colours)."""
    for axis, colour in zip(np.eye(3), ('tab:red', 'tab:green', 'tab:blue')):
        ax.plot(*np.stack([np.zeros(3), axis * size]).T, color=colour, linewidth=2.0)
    ax.text(0.0, 0.0, 0.0, ' ' + (frame_id or 'base'), fontsize=8)


def _label_3d(ax, frame_id):
    suffix = ' (%s)' % frame_id if frame_id else ''
    ax.set_xlabel('x [m]' + suffix)
    ax.set_ylabel('y [m]')
    ax.set_zlabel('z [m]')


def plot_backbones(output, backbones, goals=(), frame_id='', title='Backbone'):
    """Write a 3-D PNG of backbones ``[(label, (N, 3) positions in m)]`` and goal points."""
    plt = _pyplot()
    fig = plt.figure(figsize=(7.5, 7.0))
    ax = fig.add_subplot(projection='3d')
    colours = plt.cm.viridis(np.linspace(0.0, 0.9, max(len(backbones), 1)))
    points = [np.zeros((1, 3))]
    for (label, positions), colour in zip(backbones, colours):
        positions = np.asarray(positions, dtype=float)
        ax.plot(*positions.T, color=colour, linewidth=2.5, label=label)
        ax.scatter(*positions[-1], color=colour, s=18)
        points.append(positions)
    goals = np.asarray(goals, dtype=float).reshape(-1, 3)
    if len(goals):
        ax.scatter(*goals.T, marker='x', color='tab:red', s=50, label='goal')
        points.append(goals)
    points = np.concatenate(points)
    extent = float(np.max(np.ptp(points, axis=0))) if len(points) > 1 else 0.1
    draw_base_frame(ax, 0.15 * max(extent, 1e-3), frame_id)
    set_equal_3d(ax, points)
    _label_3d(ax, frame_id)
    ax.set_title(title)
    if backbones or len(goals):
        ax.legend(loc='upper left', fontsize=8)
    fig.tight_layout()
    fig.savefig(output, dpi=100)
    plt.close(fig)
    return output


def _snapshot(reader, snapshots, backbone):
    t, connection, raw = backbone
    msg = reader.deserialize(raw, connection.msgtype)
    if msg.poses:
        snapshots.append((t, np.array([_point(p.pose.position) for p in msg.poses])))


def _figure_backbone(rec, output):
    if rec.goal_snapshots:
        goals = np.array(rec.goals, dtype=float).reshape(-1, 4)
        backbones = [('goal %d (t = %.2f s)' % (i + 1, t), positions)
                     for i, (t, positions) in enumerate(rec.goal_snapshots)]
        return plot_backbones(output, backbones, goals=goals[:, 1:], frame_id=rec.frame_id,
                              title='Backbone at the end of each of %d goals' % len(backbones))
    backbones = [('t = %.2f s' % t, positions) for t, positions in rec.snapshots]
    return plot_backbones(output, backbones, frame_id=rec.frame_id,
                          title='Backbone at %d instants' % len(backbones))


def _figure_tip(rec, output):
    plt = _pyplot()
    tip = np.array(rec.tip, dtype=float).reshape(-1, 4)
    goals = np.array(rec.goals, dtype=float).reshape(-1, 4)
    fig = plt.figure(figsize=(13.0, 6.0))
    ax = fig.add_subplot(1, 2, 1, projection='3d')
    ax.plot(*tip[:, 1:].T, color='tab:blue', linewidth=1.5, label='tip')
    if len(tip):
        ax.scatter(*tip[0, 1:], color='tab:blue', marker='o', s=25, label='start')
    if len(goals):
        ax.scatter(*goals[:, 1:].T, color='tab:red', marker='x', s=50, label='goal')
    points = np.concatenate([np.zeros((1, 3)), tip[:, 1:], goals[:, 1:]])
    draw_base_frame(ax, 0.15 * max(float(np.max(np.ptp(points, axis=0))), 1e-3), rec.frame_id)
    set_equal_3d(ax, points)
    _label_3d(ax, rec.frame_id)
    ax.set_title('Tip path and goals')
    ax.legend(loc='upper left', fontsize=8)
    # each coordinate on an axis of its own: millimetre moves stay visible whatever the others
    end = float(tip[-1, 0]) if len(tip) else 0.0
    for i, (axis, colour) in enumerate(zip('xyz', ('tab:red', 'tab:green', 'tab:blue'))):
        sub = fig.add_subplot(3, 2, 2 * i + 2)
        sub.plot(tip[:, 0], tip[:, 1 + i] * 1e3, color=colour, label='tip %s' % axis)
        if len(goals):  # the goal in force, from when it came until the next one
            times = np.append(goals[:, 0], max(end, float(goals[-1, 0])))
            values = np.append(goals[:, 1 + i], goals[-1, 1 + i]) * 1e3
            sub.step(times, values, where='post', color='black', linestyle='--', linewidth=1.0,
                     label='goal %s' % axis)
        sub.set_ylabel('%s [mm]' % axis)
        sub.grid(True, alpha=0.3)
        sub.legend(fontsize=7, loc='upper right')
        if i == 0:
            sub.set_title('Tip coordinates over time')
        if i == 2:
            sub.set_xlabel('time [s]')
    fig.tight_layout()
    fig.savefig(output, dpi=100)
    plt.close(fig)
    return output


def cable_order(rec):
    """Cable names in the order the bag's JointStates first list them: the robot file's.

    Measured first (the driver lists every cable), then any only commanded. Not sorted:
    ``servo_1, servo_11, servo_2`` is no robot's order.
    """
    return list(dict.fromkeys([*rec.measured, *rec.commanded]))


def _figure_cables(rec, output):
    plt = _pyplot()
    names = cable_order(rec)
    fig, axes = plt.subplots(len(names), 1, figsize=(9.0, 2.2 * len(names) + 1.0), sharex=True,
                             squeeze=False)
    for ax, name in zip(axes[:, 0], names):
        if name in rec.measured:
            data = np.array(rec.measured[name])
            ax.plot(data[:, 0], data[:, 1] * 1e3, color='tab:blue', label='measured')
        if name in rec.commanded:
            data = np.array(rec.commanded[name])
            ax.plot(data[:, 0], data[:, 1] * 1e3, color='tab:orange', linestyle='--',
                    drawstyle='steps-post', label='commanded')
        ax.set_ylabel('%s [mm]' % name)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8, loc='best')
    axes[-1, 0].set_xlabel('time [s]')
    axes[0, 0].set_title('Cable lengths: commanded vs measured')
    fig.tight_layout()
    fig.savefig(output, dpi=100)
    plt.close(fig)
    return output


def _figure_solver(rec, output):
    plt = _pyplot()
    data = np.array(rec.solver, dtype=float)
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9.0, 6.0), sharex=True)
    ax1.plot(data[:, 0], data[:, 1], marker='.', label='median')
    ax1.plot(data[:, 0], data[:, 2], marker='.', label='max')
    if np.all(data[:, 1:3] > 0.0):
        ax1.set_yscale('log')
    ax1.set_ylabel('solve time [ms]')
    ax1.set_title('Statics solver (from /diagnostics)')
    ax1.grid(True, alpha=0.3)
    ax1.legend(fontsize=8)
    residual = data[:, 3]
    ax2.plot(data[:, 0], residual, marker='.', color='tab:purple')
    if np.any(residual > 0.0):
        ax2.set_yscale('log')
    ax2.set_ylabel('cable length residual [m]')
    ax2.set_xlabel('time [s]')
    ax2.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(output, dpi=100)
    plt.close(fig)
    return output


#: (file, what it needs, how to tell the data is there, figure function)
FIGURES = (
    ('backbone.png', 'a backbone (nav_msgs/Path) topic', lambda r: r.snapshots,
     _figure_backbone),
    ('tip_path.png', 'a tip_pose or backbone topic', lambda r: r.tip, _figure_tip),
    ('cable_lengths.png', 'cable_commands or cable_states', lambda r: r.commanded or r.measured,
     _figure_cables),
    ('solver.png', 'statics status on /diagnostics', lambda r: r.solver, _figure_solver),
)


def plot_bag(bag, output_dir, log=print):
    """Write the figures of ``bag`` into ``output_dir``; return the paths written."""
    rec = read_recording(bag)
    os.makedirs(output_dir, exist_ok=True)
    written = []
    for name, needs, present, figure in FIGURES:
        if present(rec):
            written.append(figure(rec, os.path.join(output_dir, name)))
        else:
            log('plot: skipped %s: the bag has no %s' % (name, needs))
    return written


def main(argv=None):
    """Plot a recording; returns the exit code (1 if nothing could be plotted)."""
    parser = argparse.ArgumentParser(
        prog='python -m continuum_statics plot', description=__doc__.splitlines()[0])
    parser.add_argument('bag', help='rosbag2 directory (or .mcap file)')
    parser.add_argument('--output', '-o', default=None,
                        help='directory for the PNGs (default <bag>_plots)')
    args = parser.parse_args(list(sys.argv[1:] if argv is None else argv))
    output = args.output or str(Path(args.bag).with_suffix('')).rstrip('/') + '_plots'
    try:
        written = plot_bag(args.bag, output)
    except ValueError as error:
        print('error: %s' % error, file=sys.stderr)
        return 1
    for path in written:
        print('plot: wrote %s' % path)
    if not written:
        print('error: nothing to plot in %s' % args.bag, file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
