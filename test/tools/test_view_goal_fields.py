"""The view's goal fields and gizmo follow the goal in force, without overwriting the user's edit.

No DDS and no browser: the page (a real viser server on a free port, no client) is redrawn from a
:class:`LiveState` the test fills as the ROS thread would.
"""
from collections import deque
import socket

import numpy as np
import pytest

from continuum_statics.tools.view import LiveState, Page, follow_goal

viser = pytest.importorskip('viser')
TIP = np.array([0.0, 0.0, 0.2])  # the straight rod's tip, m
BACKBONE = np.linspace(np.zeros(3), TIP, 11)


def test_follow_goal_moves_untouched_fields_and_keeps_an_edit():
    # before: no such rule (the fields never followed a goal, measured with the old Page below)
    goal = (0.01234567, -0.02, 0.19)
    # untouched: the fields show what the view put there -> the goal, at the fields' 0.1 mm
    assert follow_goal((0.0, 0.0, 0.2), (0.0, 0.0, 0.2), goal) == (0.0123, -0.02, 0.19)
    # the user typed 5 mm in x and has not sent it: kept (None), not overwritten
    assert follow_goal((0.005, 0.0, 0.2), (0.0, 0.0, 0.2), goal) is None
    # a difference below the fields' resolution is no edit
    assert follow_goal((0.00004, 0.0, 0.2), (0.0, 0.0, 0.2), goal) is not None


@pytest.fixture
def page():
    with socket.socket() as sock:
        sock.bind(('127.0.0.1', 0))
        port = sock.getsockname()[1]
    server = viser.ViserServer(host='127.0.0.1', port=port, verbose=False)
    try:
        yield Page(server, LiveState(), deque(), 20.0)
    finally:
        server.stop()


def test_the_goal_fields_follow_goals_from_other_clients(page):
    state = page.state
    # the view starts while a goal from another client is in force (latched tip_goal_active)
    state.update(backbone=BACKBONE, frame_id='base_link', goal=np.array([0.03, 0.01, 0.18]))
    page.refresh()
    # before: fields and gizmo at the straight tip (0, 0, 0.2)
    assert page.goal_field.value == (0.03, 0.01, 0.18)
    assert np.allclose(page.gizmo.position, (0.03, 0.01, 0.18))
    # a later goal from another client (the tip_goal service, teleop, ...)
    state.update(goal=np.array([-0.02, 0.04, 0.17]))
    page.refresh()
    # before: the fields stayed at (0, 0, 0.2)
    assert page.goal_field.value == (-0.02, 0.04, 0.17)
    assert np.allclose(page.gizmo.position, (-0.02, 0.04, 0.17))


def test_an_edit_not_sent_is_kept_until_sent(page):
    state = page.state
    state.update(backbone=BACKBONE, frame_id='base_link')
    page.refresh()
    assert page.goal_field.value == (0.0, 0.0, 0.2)  # no goal yet: the tip
    page.goal_field.value = (0.05, 0.0, 0.15)  # the user types a goal
    state.update(goal=np.array([-0.02, 0.04, 0.17]))  # another client's goal meanwhile
    page.refresh()
    assert page.goal_field.value == (0.05, 0.0, 0.15)  # the edit wins ...
    assert 'your edit, not sent' in page.status.content  # ... and the page says so
    page.send_goal()
    position, frame_id = page.outbox.popleft()
    assert np.allclose(position, (0.05, 0.0, 0.15)) and frame_id == 'base_link'
    state.update(goal=np.array([0.05, 0.0, 0.15]))  # the controller's echo of it
    page.refresh()
    state.update(goal=np.array([0.0, -0.03, 0.18]))  # sent: the next goal is followed again
    page.refresh()
    # before: the fields stayed at the sent (0.05, 0, 0.15)
    assert page.goal_field.value == (0.0, -0.03, 0.18)
    assert 'your edit' not in page.status.content
