"""Differential fuzzing: the raw CDR JointState parser against rclpy's own deserializer.

Random and mutated sensor_msgs/JointState bytes, in both byte orders and every encapsulation
kind: :func:`parse_joint_state` must accept a payload iff rclpy's ``deserialize_message`` accepts
it (and the stamp's nanosec is below 1e9), with the same content; the name-list cache of the
previous message (little- or big-endian, valid or not) must never change the answer.

The reference encoder below is written from the OMG CDR rules (XCDR1: 4-byte encapsulation
header, then every primitive aligned to its size from the origin after that header; a string is
a uint32 length counting the NUL, then the bytes; a sequence is a uint32 count, then the
elements), not from the parser. ``FUZZ_EXAMPLES`` sets the cases per test (``make fuzz``).
"""
import math
import os
import struct

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
import numpy as np
import pytest

pytest.importorskip('rclpy')
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from continuum_statics.nodes.joint_state_parser import parse_joint_state  # noqa: E402

EXAMPLES = int(os.environ.get('FUZZ_EXAMPLES', '1500'))
FUZZ = settings(max_examples=EXAMPLES, deadline=None, database=None,
                derandomize='FUZZ_EXAMPLES' not in os.environ,
                suppress_health_check=list(HealthCheck))

#: Encapsulation kinds (RTPS 10.5): 0 CDR_BE, 1 CDR_LE, 2 PL_CDR_BE, 3 PL_CDR_LE, 6..11 XCDR2.
KINDS = st.sampled_from([0, 1, 1, 1, 2, 3, 6, 7, 8, 9, 10, 11, 255])


class CdrWriter:
    """XCDR1 writer of a JointState from raw parts (strings as bytes, NUL not added)."""

    def __init__(self, big_endian, kind, options=b'\x00\x00', padding=b'\x00'):
        self.order = '>' if big_endian else '<'
        self.buffer = bytearray(bytes([0, kind]) + options)
        self.padding = padding

    def align(self, size):
        while (len(self.buffer) - 4) % size:
            self.buffer += self.padding

    def put(self, fmt, *values):
        self.align(struct.calcsize(fmt[-1]))
        self.buffer += struct.pack(self.order + fmt, *values)

    def string(self, raw):
        self.put('I', len(raw))
        self.buffer += raw

    def doubles(self, values):
        self.put('I', len(values))
        if values:
            self.put('%dd' % len(values), *values)

    def joint_state(self, sec, nanosec, frame, names, position, velocity, effort):
        self.put('i', sec)
        self.put('I', nanosec)
        self.string(frame)
        self.put('I', len(names))
        for name in names:
            self.string(name)
        for values in (position, velocity, effort):
            self.doubles(values)
        return bytes(self.buffer)


def text(raw):
    """Return a plain ROS string field as the writer takes it: UTF-8 plus the NUL."""
    return raw.encode('utf-8') + b'\x00'


floats = st.floats(allow_nan=True, allow_infinity=True)
raw_strings = st.one_of(
    st.text(max_size=12).map(text),
    st.binary(max_size=12),  # no NUL, embedded NULs, invalid UTF-8, empty
    st.sampled_from([b'', b'\x00', b'cable_0\x00', b'\xff\xfe\x00', b'a\x00b\x00',
                     '\ud800'.encode('utf-8', 'surrogatepass') + b'\x00']),
)
parts = st.fixed_dictionaries({
    'sec': st.integers(-2 ** 31, 2 ** 31 - 1),
    'nanosec': st.one_of(st.integers(0, 999_999_999), st.integers(0, 2 ** 32 - 1),
                         st.sampled_from([999_999_999, 1_000_000_000])),
    'frame': raw_strings,
    'names': st.lists(raw_strings, max_size=6),
    'position': st.lists(floats, max_size=6),
    'velocity': st.lists(floats, max_size=3),
    'effort': st.lists(floats, max_size=3),
})


@st.composite
def encoded(draw):
    """Draw a JointState as bytes: rclpy's own serialization or the reference writer's."""
    fields = draw(parts)
    if draw(st.booleans()):
        msg = JointState(name=[n.split(b'\x00')[0].decode('utf-8', 'replace')
                               for n in fields['names']],
                         position=fields['position'], velocity=fields['velocity'],
                         effort=fields['effort'])
        msg.header.stamp.sec = fields['sec']
        msg.header.stamp.nanosec = fields['nanosec']
        return serialize_message(msg)
    writer = CdrWriter(big_endian=draw(st.booleans()), kind=draw(KINDS),
                       options=draw(st.sampled_from([b'\x00\x00', b'\x00\x03', b'\xff\xff'])),
                       padding=draw(st.sampled_from([b'\x00', b'\xaa'])))
    return writer.joint_state(**fields)


@st.composite
def mutated(draw):
    """Draw encoded bytes with mutations: flips, u32 overwrites, truncation, junk, splices."""
    data = bytearray(draw(encoded()))
    for _ in range(draw(st.integers(0, 3))):
        operation = draw(st.sampled_from(['flip', 'u32', 'truncate', 'append', 'delete',
                                          'insert']))
        at = draw(st.integers(0, max(len(data) - 1, 0)))
        if operation == 'flip' and data:
            data[at] ^= 1 << draw(st.integers(0, 7))
        elif operation == 'u32' and len(data) >= 8:
            at = 4 + (at - 4) // 4 * 4 if at >= 4 else 4
            value = draw(st.sampled_from([0, 1, 2, 3, 7, 8, 255, 2 ** 31, 2 ** 32 - 1])
                         | st.integers(0, 2 ** 32 - 1))
            data[at:at + 4] = value.to_bytes(4, draw(st.sampled_from(['little', 'big'])))
        elif operation == 'truncate':
            del data[at:]
        elif operation == 'append':
            data += draw(st.binary(max_size=16))
        elif operation == 'delete':
            del data[at:at + draw(st.integers(1, 8))]
        else:
            data[at:at] = draw(st.binary(min_size=1, max_size=8))
    return bytes(data)


payloads = st.one_of(encoded(), mutated(), mutated(),
                     st.binary(max_size=96),
                     st.binary(max_size=92).map(lambda b: b'\x00\x01\x00\x00' + b))


def reference(data):
    """Return what rclpy makes of ``data``: the message, or None when it refuses it.

    A JointState takes at least 32 bytes (encapsulation 4, stamp 8, frame_id length 4, four
    sequence lengths 16); shorter payloads are refused without asking rclpy, whose Fast CDR
    segfaults on some of them (a 4-byte header announcing padding, e.g. ``00 09 00 03``).
    """
    if len(data) < 32:
        return None
    try:
        return deserialize_message(bytes(data), JointState)
    except Exception:  # RMWError
        return None


def parsed(data, previous=None):
    """Return what the parser makes of ``data``: the view, or None when it raises ValueError."""
    try:
        return parse_joint_state(data, previous)
    except ValueError:
        return None


def same_doubles(array, values):
    return np.asarray(array, dtype='<f8').tobytes() == np.asarray(values, dtype='<f8').tobytes()


def check_against_rclpy(data, view):
    msg = reference(data)
    expected = msg is not None and msg.header.stamp.nanosec < 1_000_000_000
    assert (view is not None) == expected, (data.hex(), msg)
    if view is None:
        return
    assert (view.sec, view.nanosec) == (msg.header.stamp.sec, msg.header.stamp.nanosec)
    assert view.frame_id == msg.header.frame_id
    assert view.names == list(msg.name)
    assert same_doubles(view.position, msg.position)
    assert same_doubles(view.velocity, msg.velocity)
    assert same_doubles(view.effort, msg.effort)


@FUZZ
@given(payloads)
def test_parser_accepts_what_rclpy_accepts_with_the_same_content(data):
    check_against_rclpy(data, parsed(data))


@FUZZ
@given(st.one_of(encoded(), mutated()), payloads)
def test_the_name_cache_of_any_previous_message_changes_nothing(previous, data):
    before = parsed(previous)
    key = None if before is None else before.name_bytes
    check_against_rclpy(data, parsed(data, key))


def test_a_big_endian_message_never_makes_a_malformed_little_endian_one_pass():
    # Issue 7: the cache key of a big-endian message matched the bytes of a malformed
    # little-endian message, which was then accepted with the big-endian message's names.
    names = [b'cable_0\x00', b'cable_1\x00']
    big = CdrWriter(True, 0).joint_state(1, 2, b'f\x00', names, [0.3, 0.3], [], [])
    key = parse_joint_state(big).name_bytes
    for candidate in (key if isinstance(key, bytes) else b'', b'\x00'.join(names) + b'\x01'):
        bad = CdrWriter(False, 1).joint_state(1, 2, b'f\x00', [], [], [], [])
        bad = bad[:20] + candidate + b'\xff' * 4
        assert reference(bad) is None
        with pytest.raises(ValueError, match='malformed'):
            parse_joint_state(bad, key)


@pytest.mark.parametrize('nanosec', [1_000_000_000, 2 ** 32 - 1])
def test_stamps_with_nanosec_of_a_second_or_more_are_rejected(nanosec):
    for big_endian in (False, True):
        data = CdrWriter(big_endian, 0 if big_endian else 1).joint_state(
            5, nanosec, b'\x00', [b'a\x00'], [1.0], [], [])
        assert reference(data) is not None  # rclpy takes it: the check is ours
        with pytest.raises(ValueError, match='nanosec'):
            parse_joint_state(data)


def test_empty_payload_is_reported_as_such():
    with pytest.raises(ValueError, match='empty payload'):
        parse_joint_state(b'')


def test_reference_writer_agrees_with_rclpy_on_a_plain_message():
    writer = CdrWriter(False, 1)
    data = writer.joint_state(3, 4, text('base'), [text('a'), text('bc')], [1.0, math.pi],
                              [0.5], [])
    msg = JointState(name=['a', 'bc'], position=[1.0, math.pi], velocity=[0.5])
    msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id = 3, 4, 'base'
    assert deserialize_message(data, JointState) == msg
    # byte for byte too, except rclpy's padding bytes (left uninitialized: not compared)
    theirs = serialize_message(msg)
    padding = [21, 22, 23, 34, 35, 43, 48, 49, 50, 51, 72, 73, 74, 75]
    assert len(theirs) >= len(data)
    assert [b for i, b in enumerate(data) if i not in padding] == [
        b for i, b in enumerate(theirs[:len(data)]) if i not in padding]
