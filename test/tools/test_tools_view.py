"""`python -m continuum_statics view` in a real headless browser (chromium-headless-shell).

Bringup and the view run as subprocesses, as a user starts them; the browser loads the page, a
screenshot must show the robot (pixels of the backbone's colour), and a goal typed into the page
and sent with its button must reach the controller (``tip_goal_active``) and be reached; a goal
another client then sends must show in the page's goal fields.
"""
import os
import shutil
import socket
import subprocess
import sys
import uuid

from conftest import REPO
from nodes_helpers import LATCHED, Collector, diagnostic_values, pose_xyz, stop_process, wait_until
import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import PoseStamped  # noqa: E402

from continuum_statics import load_robot  # noqa: E402
from continuum_statics.nodes.qos import COMMAND_QOS  # noqa: E402

# a browser's software renderer beside a bringup: the most CPU a test takes, on a quiet machine
pytestmark = [pytest.mark.ros, pytest.mark.alone]
BROWSER = shutil.which('chromium-headless-shell') or shutil.which('chromium')
FLAGS = ['--no-sandbox', '--disable-gpu', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
         '--disable-background-networking', '--disable-component-update', '--no-first-run',
         '--disable-sync', '--disable-quic']
ROBOT = load_robot(REPO / 'config' / 'tendon_robot.yaml')


def free_port():
    with socket.socket() as sock:
        sock.bind(('127.0.0.1', 0))
        return sock.getsockname()[1]


def orange_pixels(png):
    """Pixels of the backbone's colour (217, 140, 38) in a PNG screenshot."""
    import matplotlib.image

    image = (matplotlib.image.imread(png)[:, :, :3] * 255).astype(int)
    r, g, b = image[:, :, 0], image[:, :, 1], image[:, :, 2]
    return int(np.sum((r > 170) & (g > 100) & (g < 175) & (b < 90)))


def test_the_page_shows_the_live_robot_and_sends_a_goal_the_controller_reaches(tmp_path):
    if BROWSER is None:
        if os.environ.get('CI'):
            pytest.fail('no chromium-headless-shell (scripts/install_browser.sh failed)')
        pytest.skip('no chromium-headless-shell (apt-get install chromium-headless-shell)')
    sync_playwright = pytest.importorskip('playwright.sync_api').sync_playwright
    namespace = 'view_' + uuid.uuid4().hex[:8]
    port = free_port()
    log = open(tmp_path / 'nodes.log', 'w')
    processes = [subprocess.Popen(
        [sys.executable, '-m', 'continuum_statics', command, '--namespace', namespace, *args],
        cwd=REPO, env=os.environ.copy(), stdout=log, stderr=subprocess.STDOUT)
        for command, args in (('bringup', ()), ('view', ('--port', str(port))))]
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('view_test', namespace=namespace, context=context)
    executor = rclpy.executors.SingleThreadedExecutor(context=context)
    executor.add_node(node)
    goals = Collector(node, PoseStamped, 'tip_goal_active', LATCHED)
    tips = Collector(node, PoseStamped, 'tip_pose', LATCHED)
    diagnostics = Collector(node, DiagnosticArray, '/diagnostics', 10)
    client = node.create_publisher(PoseStamped, 'tip_goal_pose', COMMAND_QOS)

    def spin_until(predicate, timeout, what):
        def spun():
            executor.spin_once(timeout_sec=0.01)
            return predicate()
        wait_until(spun, timeout, what)

    try:
        with sync_playwright() as playwright:
            browser = playwright.chromium.launch(executable_path=BROWSER, args=FLAGS)
            page = browser.new_page(viewport={'width': 1000, 'height': 700})
            spin_until(lambda: tips.last is not None, 120.0, 'bringup ready')
            page.goto('http://127.0.0.1:%d' % port, timeout=60000)
            page.get_by_text('statics: OK').wait_for(timeout=60000)
            page.wait_for_timeout(1500)  # a few frames of the software renderer
            page.screenshot(path=str(tmp_path / 'view.png'), timeout=90000)
            pixels = orange_pixels(tmp_path / 'view.png')
            assert pixels > 500, 'the robot is not on the page (%d backbone pixels)' % pixels
            goal = np.round(ROBOT.solve_ivp([2.0, 1.0, 0.0]).tip_position, 3)  # 1 mm steps
            fields = page.locator('input[type="text"]')  # the goal's x, y, z fields
            for i in range(3):
                fields.nth(i).fill('%.3f' % goal[i])
                fields.nth(i).press('Enter')
            page.get_by_role('button', name='Send goal').click()
            spin_until(lambda: goals.last is not None and np.linalg.norm(
                pose_xyz(goals.last.pose) - goal) < 1e-6, 30.0,
                'the goal %s from the page at the controller' % goal)

            def reached():
                found = diagnostic_values(diagnostics, 'tip_controller')
                return found is not None and found[0].get('goals_reached') == '1'

            spin_until(reached, 30.0, 'the goal reached')
            assert np.linalg.norm(pose_xyz(tips.last.pose) - goal) < 2e-3
            # another client's goal: the page's fields follow it
            other = np.round(ROBOT.solve_ivp([0.0, 2.0, 1.0]).tip_position, 3)
            message = PoseStamped()
            message.header.frame_id = ROBOT.base_frame_id
            message.pose.position.x, message.pose.position.y, message.pose.position.z = (
                float(v) for v in other)
            message.pose.orientation.w = 1.0
            client.publish(message)
            spin_until(lambda: np.linalg.norm(pose_xyz(goals.last.pose) - other) < 1e-6, 30.0,
                       'the goal %s from another client at the controller' % other)

            def fields_show_it():
                shown = [float(fields.nth(i).input_value()) for i in range(3)]
                return np.allclose(shown, other, atol=1e-4)

            spin_until(fields_show_it, 10.0, 'the goal %s in the page fields' % other)
            # before: the fields stayed at the page's own goal (timed out after 10 s)
            browser.close()
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        for process in processes:
            stop_process(process)
        log.close()
