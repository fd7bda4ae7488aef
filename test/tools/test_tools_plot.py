"""``plot`` on bags written here with the ``rosbags`` writer: missing topics, SQLite, bad input.

The messages are serialized by rosbags' own CDR serializer (not by this package), so the
reader is checked against an independent writer.
"""
import subprocess
import sys

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from continuum_statics.tools import plot

PNG_SIGNATURE = b'\x89PNG\r\n\x1a\n'
STORE = get_typestore(Stores.ROS2_JAZZY)
NAMES = ['cable_0', 'cable_1', 'cable_2', 'cable_3']


def header(t):
    Time = STORE.types['builtin_interfaces/msg/Time']
    Header = STORE.types['std_msgs/msg/Header']
    return Header(stamp=Time(sec=int(t), nanosec=int((t % 1) * 1e9)), frame_id='base_link')


def joint_state(t, lengths):
    JointState = STORE.types['sensor_msgs/msg/JointState']
    return JointState(header=header(t), name=NAMES, position=np.array(lengths, dtype=float),
                      velocity=np.zeros(0), effort=np.zeros(0))


def path(t, bend):
    Path = STORE.types['nav_msgs/msg/Path']
    PoseStamped = STORE.types['geometry_msgs/msg/PoseStamped']
    Pose = STORE.types['geometry_msgs/msg/Pose']
    Point = STORE.types['geometry_msgs/msg/Point']
    Quaternion = STORE.types['geometry_msgs/msg/Quaternion']
    s = np.linspace(0.0, 0.3, 20)
    poses = [PoseStamped(header=header(t), pose=Pose(
        position=Point(x=bend * si ** 2, y=0.0, z=si), orientation=Quaternion(
            x=0.0, y=0.0, z=0.0, w=1.0))) for si in s]
    return Path(header=header(t), poses=poses)


def diagnostics(t):
    Array = STORE.types['diagnostic_msgs/msg/DiagnosticArray']
    Status = STORE.types['diagnostic_msgs/msg/DiagnosticStatus']
    KeyValue = STORE.types['diagnostic_msgs/msg/KeyValue']
    values = [KeyValue(key='solve_time_median_ms', value='%.3f' % (0.1 + 0.01 * t)),
              KeyValue(key='solve_time_max_ms', value='0.4'),
              KeyValue(key='residual_m', value='%.3g' % (1e-9 * (1 + t)))]
    return Array(header=header(t), status=[Status(
        level=0, name='continuum/statics', message='ok', hardware_id='robot',
        values=values)])


def write_bag(directory, topics, storage=StoragePlugin.MCAP, seconds=5, rate=20):
    """Write ``topics`` {name: (type, make(t))} for ``seconds`` at ``rate`` Hz."""
    with Writer(directory, version=9, storage_plugin=storage) as writer:
        connections = {name: writer.add_connection(name, msgtype, typestore=STORE)
                       for name, (msgtype, _) in topics.items()}
        for i in range(seconds * rate):
            t = i / rate
            for name, (msgtype, make) in topics.items():
                data = STORE.serialize_cdr(make(t), msgtype)
                writer.write(connections[name], int((100 + t) * 1e9), data)
    return directory


FULL = {
    '/continuum/backbone': ('nav_msgs/msg/Path', lambda t: path(t, 0.5 * t)),
    '/continuum/cable_states': ('sensor_msgs/msg/JointState',
                                lambda t: joint_state(t, [0.3 - 1e-3 * t] * 4)),
    '/continuum/cable_commands': ('sensor_msgs/msg/JointState',
                                  lambda t: joint_state(t, [0.3 - 1.2e-3 * t] * 4)),
    '/diagnostics': ('diagnostic_msgs/msg/DiagnosticArray', diagnostics),
}


def run_plot(*args):
    return subprocess.run([sys.executable, '-m', 'continuum_statics', 'plot', *map(str, args)],
                          capture_output=True, text=True, timeout=300)


def assert_png(file):
    data = file.read_bytes()
    assert data.startswith(PNG_SIGNATURE) and len(data) > 15000, file


@pytest.mark.parametrize('storage', [StoragePlugin.MCAP, StoragePlugin.SQLITE3])
@pytest.mark.ros
def test_every_figure_from_an_independently_written_bag(tmp_path, storage):
    bag = write_bag(tmp_path / 'bag', FULL, storage)
    result = run_plot(bag, '--output', tmp_path / 'png')
    assert result.returncode == 0, result.stderr
    for name in ('backbone.png', 'tip_path.png', 'cable_lengths.png', 'solver.png'):
        assert_png(tmp_path / 'png' / name)
    rec = plot.read_recording(bag)
    # Snapshots spread over the recording, tip path from the backbone (no tip_pose topic).
    times = [t for t, _ in rec.snapshots]
    assert len(times) == plot.SNAPSHOTS and times[0] == 0.0 and times[-1] == pytest.approx(4.95)
    np.testing.assert_allclose(rec.snapshots[-1][1][-1], [0.5 * 4.95 * 0.09, 0.0, 0.3])
    assert len(rec.tip) == 100 and rec.frame_id == 'base_link'
    assert rec.commanded['cable_2'][-1] == pytest.approx((4.95, 0.3 - 1.2e-3 * 4.95))
    assert rec.solver[0][1:] == pytest.approx((0.1, 0.4, 1e-9))


@pytest.mark.ros
def test_a_bag_without_some_topics_gives_the_figures_it_can(tmp_path):
    only_cables = {name: FULL[name] for name in ('/continuum/cable_states',)}
    bag = write_bag(tmp_path / 'bag', only_cables)
    result = run_plot(bag, '--output', tmp_path / 'png')
    assert result.returncode == 0, result.stderr
    assert sorted(p.name for p in (tmp_path / 'png').iterdir()) == ['cable_lengths.png']
    assert_png(tmp_path / 'png' / 'cable_lengths.png')
    for skipped in ('backbone.png', 'tip_path.png', 'solver.png'):
        assert 'skipped %s' % skipped in result.stdout


@pytest.mark.ros
def test_default_output_directory_is_next_to_the_bag(tmp_path):
    bag = write_bag(tmp_path / 'run1', {'/diagnostics': FULL['/diagnostics']}, seconds=2)
    result = run_plot(bag)
    assert result.returncode == 0, result.stderr
    assert_png(tmp_path / 'run1_plots' / 'solver.png')


@pytest.mark.ros
def test_bags_without_anything_to_plot_or_unreadable_are_clear_errors(tmp_path):
    bag = write_bag(tmp_path / 'other', {'/chatter': (
        'std_msgs/msg/String', lambda t: STORE.types['std_msgs/msg/String'](data='hi'))})
    result = run_plot(bag, '--output', tmp_path / 'png')
    assert result.returncode == 1 and 'nothing to plot' in result.stderr
    result = run_plot(tmp_path / 'missing')
    assert result.returncode == 1 and 'no such bag' in result.stderr
    broken = tmp_path / 'broken'
    broken.mkdir()
    (broken / 'metadata.yaml').write_text('not: [a, bag')
    result = run_plot(broken)
    assert result.returncode == 1 and 'cannot read bag' in result.stderr


def test_long_recordings_are_thinned_evenly(tmp_path, monkeypatch):
    bag = write_bag(tmp_path / 'bag', FULL, seconds=5, rate=20)
    monkeypatch.setattr(plot, 'MAX_POINTS', 30)
    rec = plot.read_recording(bag)
    # 100 messages per series, at most 30 kept: every 4th, from the first on.
    assert [t for t, *_ in rec.tip] == pytest.approx([0.2 * i for i in range(25)])
    assert len(rec.measured['cable_0']) == 25 and len(rec.solver) == 25
    assert len(rec.snapshots) == plot.SNAPSHOTS  # snapshots are picked by time, not thinned


def test_goals_from_the_topic_and_the_controller_diagnostics_count_once(tmp_path):
    """A streamed goal echoed in the controller's ``goal_m`` counts once; a service goal too."""
    PoseStamped = STORE.types['geometry_msgs/msg/PoseStamped']
    Pose = STORE.types['geometry_msgs/msg/Pose']
    Point = STORE.types['geometry_msgs/msg/Point']
    Quaternion = STORE.types['geometry_msgs/msg/Quaternion']
    Array = STORE.types['diagnostic_msgs/msg/DiagnosticArray']
    Status = STORE.types['diagnostic_msgs/msg/DiagnosticStatus']
    KeyValue = STORE.types['diagnostic_msgs/msg/KeyValue']
    first, second = (0.05, 0.0, 0.29), (-0.04, 0.03, 0.285)
    goal_msg = PoseStamped(header=header(0.0), pose=Pose(
        position=Point(x=first[0], y=first[1], z=first[2]),
        orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)))

    def controller(t):
        goal = first if t < 2.5 else second
        return Array(header=header(t), status=[Status(
            level=0, name='continuum/tip_controller', message='moving', hardware_id='robot',
            values=[KeyValue(key='goal_m', value='%.5f %.5f %.5f' % goal)])])

    bag = tmp_path / 'bag'
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        goals = writer.add_connection('/continuum/tip_goal_pose', 'geometry_msgs/msg/PoseStamped',
                                      typestore=STORE)
        diag = writer.add_connection('/diagnostics', 'diagnostic_msgs/msg/DiagnosticArray',
                                     typestore=STORE)
        writer.write(goals, int(100e9), STORE.serialize_cdr(goal_msg, goals.msgtype))
        for i in range(1, 6):
            writer.write(diag, int((100 + i) * 1e9),
                         STORE.serialize_cdr(controller(float(i)), diag.msgtype))
    rec = plot.read_recording(bag)
    assert [g[0] for g in rec.goals] == [0.0, 3.0]
    np.testing.assert_allclose([g[1:] for g in rec.goals], [first, second])


@pytest.mark.ros
def test_the_backbone_at_the_end_of_each_goal_and_goals_from_the_active_goal_topic(tmp_path):
    """Goals from tip_goal_active; a snapshot is the last backbone before the next goal."""
    PoseStamped = STORE.types['geometry_msgs/msg/PoseStamped']
    Pose = STORE.types['geometry_msgs/msg/Pose']
    Point = STORE.types['geometry_msgs/msg/Point']
    Quaternion = STORE.types['geometry_msgs/msg/Quaternion']

    def goal(t, x):
        orientation = Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)
        return PoseStamped(header=header(t), pose=Pose(position=Point(x=x, y=0.0, z=0.29),
                                                       orientation=orientation))

    bag = tmp_path / 'bag'
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        active = writer.add_connection('/continuum/tip_goal_active',
                                       'geometry_msgs/msg/PoseStamped', typestore=STORE)
        backbone = writer.add_connection('/continuum/backbone', 'nav_msgs/msg/Path',
                                         typestore=STORE)
        for i in range(50):  # 5 s of backbones bending further; goals at 0, 2 and 4 s
            t = i / 10
            if i in (0, 20, 40):
                writer.write(active, int((100 + t) * 1e9),
                             STORE.serialize_cdr(goal(t, 0.01 * i), active.msgtype))
            writer.write(backbone, int((100 + t) * 1e9),
                         STORE.serialize_cdr(path(t, 0.1 * i), backbone.msgtype))
    rec = plot.read_recording(bag)
    assert [round(g[0], 3) for g in rec.goals] == [0.0, 2.0, 4.0]
    # the last backbone before 2 s (i = 19), before 4 s (i = 39), and the last one (i = 49)
    assert [round(t, 3) for t, _ in rec.goal_snapshots] == [1.9, 3.9, 4.9]
    np.testing.assert_allclose(rec.goal_snapshots[0][1][-1], [0.1 * 19 * 0.09, 0.0, 0.3])
    result = run_plot(bag, '--output', tmp_path / 'plots')
    assert result.returncode == 0, result.stderr
    assert_png(tmp_path / 'plots' / 'backbone.png')
    assert_png(tmp_path / 'plots' / 'tip_path.png')


def test_cables_are_drawn_in_the_robot_files_order(tmp_path, monkeypatch):
    """The v6 robot's cables as its file lists them, not as their names sort."""
    v6 = ['servo_1', 'servo_20', 'servo_23', 'servo_9', 'servo_6', 'servo_11']
    JointState = STORE.types['sensor_msgs/msg/JointState']

    def state(t):
        return JointState(header=header(t), name=v6, position=np.full(len(v6), 0.3 - 1e-3 * t),
                          velocity=np.zeros(0), effort=np.zeros(0))

    bag = write_bag(tmp_path / 'bag', {
        '/continuum/cable_states': ('sensor_msgs/msg/JointState', state),
        '/continuum/cable_commands': ('sensor_msgs/msg/JointState', state)}, seconds=1)
    figures = []
    import matplotlib.pyplot as plt

    monkeypatch.setattr(plt, 'close', figures.append)  # keep the figure to read its axes
    plot.plot_bag(bag, tmp_path / 'png', log=lambda text: None)
    monkeypatch.undo()
    labels = [ax.get_ylabel() for ax in figures[0].axes]
    # before: servo_1, servo_11, servo_20, servo_23, servo_6, servo_9 (sorted by name)
    assert labels == ['%s [mm]' % name for name in v6], labels
    assert plot.cable_order(plot.read_recording(bag)) == v6
    for figure in figures:
        plt.close(figure)
