"""Recorded runs from CSV (the real FTDCR v6 subset, the project's own layout) and rosbag2."""
import argparse
import dataclasses

from conftest import REPO
import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from continuum_statics import load_robot
from continuum_statics.calibration.recorded_run import (
    ColumnMap,
    add_column_arguments,
    column_map_from_args,
    read_recorded_run,
)
from continuum_statics.calibration.runs import read_run

V6 = REPO / 'test' / 'data' / 'ftdcr_v6' / 'tendon_pull_subset.csv'
V6_OPTIONS = ['--cable-columns', 'servo_3_mm,servo_1_mm,servo_20_mm,servo_23_mm,servo_9_mm,'
              'servo_6_mm,servo_11_mm,servo_24_mm,servo_2_mm',  # not the header order
              '--cable-kind', 'displacement', '--cable-sign', '1', '--cable-scale', '0.001',
              '--tip-columns', 'tip_x,tip_y,tip_z', '--tip-scale', '0.001']
CABLES9 = ['t%d' % j for j in range(9)]
STRAIGHT9 = [0.2 + 0.01 * j for j in range(9)]


def parse(options):
    parser = argparse.ArgumentParser()
    add_column_arguments(parser)
    return column_map_from_args(parser.parse_args(options))


def test_options_build_the_v6_column_map():
    assert parse(V6_OPTIONS) == ColumnMap(
        cables=('servo_3_mm', 'servo_1_mm', 'servo_20_mm', 'servo_23_mm', 'servo_9_mm',
                'servo_6_mm', 'servo_11_mm', 'servo_24_mm', 'servo_2_mm'),
        kind='displacement', sign=1.0, scale=0.001, tip_scale=0.001)
    assert parse([]) == ColumnMap()


def test_v6_displacements_become_lengths_in_the_given_column_order():
    run = read_recorded_run(V6, CABLES9, STRAIGHT9, parse(V6_OPTIONS))
    assert run.lengths.shape == (60, 9) and run.tips.shape == (60, 3) and len(run.labels) == 60
    assert run.source == str(V6)
    # data row 2: 1775513851.156998,rep1_tendon0_id1_pull,servo_1 -0.82835,servo_20 -0.766991,
    # servo_23 -0.598253,servo_9 -0.751651,servo_6 -0.705631,servo_11 -0.751651,
    # servo_24 -0.690291,servo_2 -0.674952,servo_3 -0.889709, tip -9.329032,0.381877,234.26901
    # (mm); a negative value pays the cable out: longer than straight
    np.testing.assert_allclose(run.lengths[1], [
        0.200889709, 0.21082835, 0.220766991, 0.230598253, 0.240751651, 0.250705631,
        0.260751651, 0.270690291, 0.280674952], rtol=0, atol=1e-12)
    np.testing.assert_allclose(run.tips[1], [-0.009329032, 0.000381877, 0.23426901],
                               rtol=0, atol=1e-12)
    assert run.times[1] == pytest.approx(1775513851.156998, abs=1e-6)
    assert run.labels[1] == 'rep1_tendon0_id1_pull'
    assert run.labels[50] == 'rep1_tendon2_id23_pull_hold'
    assert np.all(np.diff(run.times) >= 0)
    # row 14 pulls servo_1 by 3.390098 mm: 3.39 mm shorter than straight (column 1 here)
    assert run.lengths[13, 1] == pytest.approx(0.21 - 0.003390098, abs=1e-12)
    # the opposite sign pays out what the other pulls
    flipped = read_recorded_run(V6, CABLES9, STRAIGHT9,
                                parse(V6_OPTIONS + ['--cable-sign', '-1']))
    assert flipped.lengths[13, 1] == pytest.approx(0.21 + 0.003390098, abs=1e-12)


def test_subset_keeps_the_chosen_samples():
    run = read_recorded_run(V6, CABLES9, STRAIGHT9, parse(V6_OPTIONS))
    held = run.subset([label.endswith('_hold') for label in run.labels])
    assert held.labels == ('rep1_tendon2_id23_pull_hold',) and len(held) == 1
    np.testing.assert_array_equal(held.lengths[0], run.lengths[50])
    picked = run.subset([3, 1])
    assert picked.times.tolist() == [run.times[3], run.times[1]]
    np.testing.assert_array_equal(picked.tips, run.tips[[3, 1]])
    assert picked.labels == (run.labels[3], run.labels[1])


def test_length_columns_named_as_cables(tmp_path):
    data = tmp_path / 'run.csv'
    data.write_text('# lengths in m, tips in m, base frame\n'
                    'tip_z,c1,tip_x,c0,tip_y,c2\n'
                    '0.30,0.101,0.01,0.100,0.02,0.102\n'
                    '\n'
                    '# a comment between rows\n'
                    '0.29,0.111,0.03,0.110,0.04,0.112\n')
    run = read_recorded_run(data, ['c0', 'c1', 'c2'], None)
    np.testing.assert_array_equal(run.lengths, [[0.100, 0.101, 0.102], [0.110, 0.111, 0.112]])
    np.testing.assert_array_equal(run.tips, [[0.01, 0.02, 0.30], [0.03, 0.04, 0.29]])
    np.testing.assert_array_equal(run.times, [0.0, 1.0])  # no timestamp column: numbered
    assert run.labels == ('', '')


def test_other_sensors_columns_are_read_with_the_tips_scale_and_gaps(tmp_path):
    data = tmp_path / 'run.csv'
    data.write_text('timestamp,c0,c1,tip_x,tip_y,tip_z,em_coil_x,em_coil_y,em_coil_z,other_x\n'
                    '0.0,0.1,0.1,1,2,300,4,5,150,9\n'
                    '0.1,0.1,0.1,1,2,300,,,,9\n'      # the coil gave nothing on this row
                    '0.2,0.1,0.1,1,2,300,nan,nan,nan,9\n'
                    '0.3,0.1,0.1,1,2,300,6,7,151,9\n')
    with pytest.raises(ValueError, match='has other_x but not other_y, other_z'):
        read_recorded_run(data, ['c0', 'c1'], None, sensor_names=['em_coil', 'other'])
    run = read_recorded_run(data, ['c0', 'c1'], None, ColumnMap(tip_scale=0.001),
                            sensor_names=['em_coil', 'absent'])
    assert list(run.points) == ['em_coil']
    np.testing.assert_array_equal(run.points['em_coil'][[0, 3]],
                                  [[0.004, 0.005, 0.150], [0.006, 0.007, 0.151]])
    assert np.all(np.isnan(run.points['em_coil'][1:3]))
    np.testing.assert_array_equal(run.subset([3, 0]).points['em_coil'],
                                  run.points['em_coil'][[3, 0]])
    assert read_recorded_run(data, ['c0', 'c1'], None).points == {}  # not asked: not read
    data.write_text(data.read_text().replace(',6,7,', ',6,x7,'))
    with pytest.raises(ValueError, match=r'row 4 \(line 5\), column em_coil_y: .x7. is not a'):
        read_recorded_run(data, ['c0', 'c1'], None, sensor_names=['em_coil'])


def test_calibrate_reads_the_robot_files_other_sensors_and_not_its_tip_tracker(tmp_path):
    robot = load_robot(REPO / 'config' / 'tendon_robot_sensors.yaml')  # tip_tracker, em_coil
    names = ['%s_%s' % (sensor, axis) for sensor in ('tip_tracker', 'em_coil') for axis in 'xyz']
    data = tmp_path / 'run.csv'
    data.write_text(','.join(list(robot.cable_names) + ['tip_x', 'tip_y', 'tip_z'] + names)
                    + '\n' + ','.join(['%.6f' % x for x in robot.straight_cable_lengths]
                                      + ['0', '0', '0.3', '0', '0', '0.3', '0', '0', '0.15'])
                    + '\n')
    run = read_run(data, robot, ColumnMap())
    assert list(run.points) == ['em_coil']  # the tip tracker's points are the run's tips
    np.testing.assert_array_equal(run.points['em_coil'], [[0.0, 0.0, 0.15]])


GOOD = 'timestamp,c0,c1,tip_x,tip_y,tip_z\n0.0,0.1,0.1,0,0,0.3\n0.5,0.1,0.1,0,0,0.3\n'


@pytest.mark.parametrize('text, expected', [
    (GOOD.replace('c1,', 'cable_1,'), ['lacks', 'c1', 'timestamp,c0,cable_1,tip_x']),
    (GOOD.replace('tip_y', 'tipy'), ['lacks', 'tip_y']),
    (GOOD.replace('0.5,0.1,0.1', '0.5,0.1,abc'), ['row 2 (line 3)', 'column c1', 'abc']),
    (GOOD.replace('0,0,0.3\n0.5', 'nan,0,0.3\n0.5'), ['row 1 (line 2)', 'column tip_x']),
    (GOOD.replace('0.5,', '-0.5,'), ['row 2 (line 3)', 'column timestamp', 'time order']),
    (GOOD.replace('0.5,0.1,0.1,', '0.5,0.1,'), ['row 2 (line 3)', '5 cells', 'has 6']),
    ('# nothing but a comment\n', ['empty']),
    (GOOD.split('\n')[0] + '\n', ['no data rows']),
])
def test_errors_name_the_file_row_and_column(tmp_path, text, expected):
    data = tmp_path / 'bad.csv'
    data.write_text(text)
    with pytest.raises(ValueError) as error:
        read_recorded_run(data, ['c0', 'c1'], None)
    for part in [str(data)] + expected:
        assert part in str(error.value)


def test_cable_column_count_must_match_the_robot():
    with pytest.raises(ValueError, match='2 cable columns'):
        read_recorded_run(V6, CABLES9, STRAIGHT9,
                          ColumnMap(cables=('servo_1_mm', 'servo_3_mm'), kind='displacement'))


# -- rosbag2 ------------------------------------------------------------------------------
STORE = get_typestore(Stores.ROS2_JAZZY)
ROBOT_CABLES = ['c0', 'c1', 'c2']
BAG_NAMES = ['c2', 'c0', 'c1']  # cable_states lists them in another order
STATE_LATENCY = 0.001  # s from a message's header stamp to the bag's receive time
TIP_LATENCY = 0.08     # tracker latency: receive times would pair tips with later states


def header(t):
    Time = STORE.types['builtin_interfaces/msg/Time']
    Header = STORE.types['std_msgs/msg/Header']
    sec = int(t)
    return Header(stamp=Time(sec=sec, nanosec=round((t - sec) * 1e9)), frame_id='world')


def bag_lengths(k):
    """cable_states message k: robot cable j is 0.1 + 0.01 j + 0.001 k (m), in BAG_NAMES order."""
    return [0.1 + 0.01 * ROBOT_CABLES.index(name) + 0.001 * k for name in BAG_NAMES]


def write_bag(directory, tip_times, stamped=True, names=BAG_NAMES, delays=None, coil=()):
    """cable_states at 10 Hz from 1000 s (stamp 1000 + k/10), a tip at each of ``tip_times``.

    ``delays`` {('states' or 'tip', index): s} adds to a message's receive time; ``coil``
    [(stamp s, (x, y, z) m, frame id)] on ``/em/sensors/em_coil``
    (PoseWithCovarianceStamped).
    """
    delays = delays or {}
    JointState = STORE.types['sensor_msgs/msg/JointState']
    PoseStamped = STORE.types['geometry_msgs/msg/PoseStamped']
    Pose = STORE.types['geometry_msgs/msg/Pose']
    Point = STORE.types['geometry_msgs/msg/Point']
    Quaternion = STORE.types['geometry_msgs/msg/Quaternion']
    messages = []
    for k in range(10):
        t = 1000.0 + 0.1 * k
        msg = JointState(header=header(t if stamped else 0.0), name=list(names),
                         position=np.array(bag_lengths(k)), velocity=np.zeros(0),
                         effort=np.zeros(0))
        messages.append((t + STATE_LATENCY + delays.get(('states', k), 0.0), 'states', msg))
    for i, t in enumerate(tip_times):
        msg = PoseStamped(header=header(t if stamped else 0.0), pose=Pose(
            position=Point(x=0.001 * i, y=-0.002 * i, z=0.3),
            orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)))
        latency = (TIP_LATENCY if stamped else 0.0) + delays.get(('tip', i), 0.0)
        messages.append((t + latency, 'tip', msg))
    Covariant = STORE.types['geometry_msgs/msg/PoseWithCovariance']
    for t, (x, y, z), frame in coil:
        msg = STORE.types['geometry_msgs/msg/PoseWithCovarianceStamped'](
            header=dataclasses.replace(header(t), frame_id=frame), pose=Covariant(
                pose=Pose(position=Point(x=x, y=y, z=z),
                          orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)),
                covariance=np.zeros(36)))
        messages.append((t + 0.03, 'coil', msg))
    with Writer(directory, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connections = {
            'states': writer.add_connection('/continuum/cable_states',
                                            'sensor_msgs/msg/JointState', typestore=STORE),
            'tip': writer.add_connection('/mocap/tip_pose_measured',
                                         'geometry_msgs/msg/PoseStamped', typestore=STORE),
            'coil': writer.add_connection('/em/sensors/em_coil',
                                          'geometry_msgs/msg/PoseWithCovarianceStamped',
                                          typestore=STORE)}
        for received, role, msg in sorted(messages, key=lambda m: m[0]):
            writer.write(connections[role], round(received * 1e9),
                         STORE.serialize_cdr(msg, connections[role].msgtype))
    return directory


TIP_STAMPS = [999.95, 1000.0, 1000.25, 1000.3, 1000.67, 1000.95]


@pytest.mark.parametrize('stamped, times, states', [
    # header stamps: a tip pairs with the state stamped at or before it (999.95: none yet)
    (True, [1000.0, 1000.25, 1000.3, 1000.67, 1000.95], [0, 2, 3, 6, 9]),
    # zero stamps: receive times, states arriving 1 ms after 1000 + k/10 (so 1000.0 has none
    # yet and 1000.3 still pairs with state 2)
    (False, [1000.25, 1000.3, 1000.67, 1000.95], [2, 2, 6, 9]),
])
def test_bag_pairs_each_tip_with_the_latest_cable_states(tmp_path, stamped, times, states):
    bag = write_bag(tmp_path / 'run', TIP_STAMPS, stamped=stamped)
    run = read_recorded_run(bag, ROBOT_CABLES, None)
    np.testing.assert_allclose(run.times, times, rtol=0, atol=1e-6)
    # robot order c0, c1, c2 although the bag lists c2, c0, c1
    expected = [[0.1 + 0.001 * k, 0.11 + 0.001 * k, 0.12 + 0.001 * k] for k in states]
    np.testing.assert_allclose(run.lengths, expected, rtol=0, atol=1e-12)
    i = [TIP_STAMPS.index(t) for t in times]
    np.testing.assert_allclose(run.tips, [[0.001 * j, -0.002 * j, 0.3] for j in i])
    assert run.labels == ('',) * len(times) and run.source == str(bag)


def test_bag_stamps_win_over_receive_times(tmp_path):
    # tip stamped 1000.25 is received at 1000.33: after state 3 arrived, yet state 2 is right
    bag = write_bag(tmp_path / 'run', [1000.25])
    run = read_recorded_run(bag, ROBOT_CABLES, None)
    assert run.times.tolist() == pytest.approx([1000.25])
    np.testing.assert_allclose(run.lengths[0], [0.102, 0.112, 0.122], rtol=0, atol=1e-12)


def test_bag_messages_received_out_of_stamp_order(tmp_path):
    # state 3 (stamp 1000.3) arrives after state 4; the tip stamped 1000.35 after the one
    # stamped 1000.42: pairing and sample order follow the stamps
    bag = write_bag(tmp_path / 'run', [1000.35, 1000.42], delays={
        ('states', 3): 0.15, ('tip', 0): 0.2})
    run = read_recorded_run(bag, ROBOT_CABLES, None)
    np.testing.assert_allclose(run.times, [1000.35, 1000.42], rtol=0, atol=1e-6)
    np.testing.assert_allclose(run.lengths[:, 0], [0.103, 0.104], rtol=0, atol=1e-12)
    np.testing.assert_allclose(run.tips[:, 0], [0.0, 0.001])


def test_bag_read_from_its_mcap_file_and_by_full_topic(tmp_path):
    bag = write_bag(tmp_path / 'run', [1000.25, 1000.5])
    (mcap,) = bag.glob('*.mcap')
    run = read_recorded_run(mcap, ROBOT_CABLES, None, tip_topic='/mocap/tip_pose_measured')
    assert len(run) == 2 and run.source == str(mcap)
    with pytest.raises(ValueError, match='no .../tip_pose PoseStamped topic'):
        read_recorded_run(bag, ROBOT_CABLES, None, tip_topic='tip_pose')


@pytest.mark.parametrize('names, expected', [
    (['c2', 'c0', 'cx'], 'unknown: cx'),
    (['c2', 'c0'], 'missing: c1'),
])
def test_bag_cable_names_must_be_the_robots(tmp_path, names, expected):
    bag = write_bag(tmp_path / 'run', [1000.25], names=names)
    with pytest.raises(ValueError, match=expected) as error:
        read_recorded_run(bag, ROBOT_CABLES, None)
    assert str(bag) in str(error.value)


def test_bag_sensor_points_pair_with_the_nearest_tip_sample_or_none(tmp_path):
    # tips at 1000.25 / 1000.5 / 1000.75; the coil 5 ms after the first, 15 ms before the
    # third (the nearer of two), none within 20 ms of the second
    coil = [(1000.255, (0.0, 0.0, 0.15), 'world'), (1000.45, (9.0, 9.0, 9.0), 'world'),
            (1000.735, (0.01, 0.0, 0.15), 'world'), (1000.72, (8.0, 8.0, 8.0), 'world')]
    bag = write_bag(tmp_path / 'run', [1000.25, 1000.5, 1000.75], coil=coil)
    run = read_recorded_run(bag, ROBOT_CABLES, None, sensor_names=['em_coil', 'absent'])
    assert list(run.points) == ['em_coil']
    np.testing.assert_allclose(run.points['em_coil'][[0, 2]], [[0.0, 0.0, 0.15],
                                                               [0.01, 0.0, 0.15]])
    assert np.all(np.isnan(run.points['em_coil'][1]))
    assert read_recorded_run(bag, ROBOT_CABLES, None).points == {}  # not asked: not read
    assert run.notes == ()
    other = write_bag(tmp_path / 'other', [1000.25], coil=[(1000.25, (0, 0, 0.15), 'em')])
    run = read_recorded_run(other, ROBOT_CABLES, None, sensor_names=['em_coil'])
    assert run.points == {} and len(run.tips) == 1  # the tips are read as before
    assert run.notes == ("sensors/em_coil is in frame em, the tips in world: left out (its "
                         "points are read in the tips' frame)",)
