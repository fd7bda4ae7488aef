"""doc/nodes.md states the QoS of every topic the nodes publish, as the code creates it.

The nodes' sources are read (no DDS): every ``create_publisher(type, topic, qos)`` and every
subscription (``create_subscription`` and the intake's ``add``) under
``continuum_statics/nodes/``, its QoS resolved to (reliability, durability, depth) through
``nodes/qos.py`` and rclpy. Each published topic needs a row whose QoS cell is that triple; a
``read:`` cell (an input the package does not publish) must be the nodes' subscription QoS.
"""
import ast
import re

from conftest import REPO
import pytest

rclpy_qos = pytest.importorskip('rclpy.qos')

NODES = REPO / 'continuum_statics' / 'nodes'
#: Topic arguments that are not literals: what they name in the table.
TOPIC_EXPRESSIONS = {
    'backend.command_topic': '<controller>/commands',  # drivers/ros2_control.py
    'tip_wrench_topic(self._params)': 'tip_wrench',      # or tip_wrench_estimate (published)
    'tip_wrench_topic(self._params, self.robot)': 'tip_wrench',
    'self._tip_load.topic': 'tip_wrench',              # statics: tip_wrench_topic(...) above
    'tracker_topic(self.robot)': 'tip_pose_measured',    # or sensors/<name>/accepted (published)
}
#: Subscriptions whose topic is the user's (ros2_control's joint_states parameter) or internal.
UNNAMED = {'backend.state_topic', 'topic'}


def describe(profile):
    """'reliable, transient local, 1' for a QoSProfile (or an int: rclpy's depth shorthand)."""
    if isinstance(profile, int):
        profile = rclpy_qos.QoSProfile(depth=profile)
    reliability = {rclpy_qos.ReliabilityPolicy.RELIABLE: 'reliable',
                   rclpy_qos.ReliabilityPolicy.BEST_EFFORT: 'best effort'}[profile.reliability]
    durability = {rclpy_qos.DurabilityPolicy.VOLATILE: 'volatile',
                  rclpy_qos.DurabilityPolicy.TRANSIENT_LOCAL: 'transient local'}[
        profile.durability]
    return '%s, %s, %d' % (reliability, durability, profile.depth)


def _namespace():
    from continuum_statics.nodes import qos
    names = {name: getattr(rclpy_qos, name) for name in dir(rclpy_qos)
             if name.startswith('qos_profile_')}
    names.update({name: value for name, value in vars(qos).items() if name.endswith('_QOS')})
    names['measurement_queue_qos'] = qos.measurement_queue_qos
    return names


def _topic(expression):
    if isinstance(expression, ast.Constant) and isinstance(expression.value, str):
        return expression.value
    if isinstance(expression, ast.BinOp) and isinstance(expression.left, ast.Constant):
        return expression.left.value.replace('%s', '<name>')  # 'sensors/%s' % sensor.name
    text = ast.unparse(expression)
    if text in UNNAMED:
        return None
    assert text in TOPIC_EXPRESSIONS, 'a topic the test cannot name: %s' % text
    return TOPIC_EXPRESSIONS[text]


def _qos_calls(kinds):
    """{topic: {qos description}} of the nodes' calls of ``kinds`` (publisher or subscriptions)."""
    namespace = _namespace()
    found = {}
    for path in sorted(NODES.glob('*.py')):
        tree = ast.parse(path.read_text())
        functions = {node.name: node for node in ast.walk(tree)
                     if isinstance(node, ast.FunctionDef)}
        for function in functions.values():
            for call in ast.walk(function):
                if not (isinstance(call, ast.Call) and isinstance(call.func, ast.Attribute)
                        and call.func.attr in kinds):
                    continue
                position = 2 if call.func.attr == 'create_publisher' else 3
                if len(call.args) <= position:
                    continue  # another method called add
                topic = _topic(call.args[1])
                if topic is None:
                    continue
                qos = call.args[position]
                parameters = [a.arg for a in function.args.args]
                if isinstance(qos, ast.Name) and qos.id in parameters:  # the caller's QoS
                    index = parameters.index(qos.id)
                    qos_values = [_caller_argument(function.name, index, namespace)]
                elif isinstance(qos, ast.Call):  # measurement_queue_qos(depth): a parameter
                    qos_values = []
                else:
                    qos_values = [eval(compile(ast.Expression(qos), str(path), 'eval'),  # noqa: S307
                                       dict(namespace))]
                found.setdefault(topic, set()).update(describe(q) for q in qos_values)
    return found


def _caller_argument(name, index, namespace):
    for path in NODES.glob('*.py'):
        for call in ast.walk(ast.parse(path.read_text())):
            if isinstance(call, ast.Call) and ast.unparse(call.func).split('.')[-1] == name:
                return eval(ast.unparse(call.args[index]), dict(namespace))  # noqa: S307
    raise AssertionError('no call of %s' % name)


def table():
    """{name: QoS cell} of doc/nodes.md's interface table."""
    rows = {}
    lines = (REPO / 'doc' / 'nodes.md').read_text().splitlines()
    header = lines.index('| name | type | who | QoS | notes |')
    for line in lines[header + 2:]:
        if not line.startswith('| `'):
            break
        cells = [cell.strip() for cell in line.strip('|').split(' | ')]
        rows[re.match(r'`([^`]+)`', cells[0]).group(1)] = cells[3]
    return rows


def test_every_published_topic_has_its_publishers_qos_in_nodes_md():
    published = _qos_calls({'create_publisher'})
    assert {'cable_states', 'backbone', 'sim/tip_pose_true', '/tf', '<controller>/commands',
            'sensors/<name>/accepted'} <= set(published)
    rows = table()
    wrong = []
    for topic, qos in sorted(published.items()):
        assert len(qos) == 1, 'publishers of %s disagree: %s' % (topic, qos)
        if rows.get(topic) != next(iter(qos)):
            wrong.append('%s: table %r, code %r' % (topic, rows.get(topic), next(iter(qos))))
    assert not wrong, wrong
    assert rows['sim/tip_pose_true'].startswith('best effort')


def test_read_cells_are_inputs_with_the_nodes_subscription_qos():
    published = _qos_calls({'create_publisher'})
    read = _qos_calls({'create_subscription', 'add'})
    rows = table()
    inputs = {name: cell[len('read: '):] for name, cell in rows.items()
              if cell.startswith('read: ')}
    assert {'tip_wrench', 'tip_twist', 'sensors/<name>'} <= set(inputs)
    for name, cell in inputs.items():
        assert name not in published, '%s is published by a node: give its QoS' % name
        assert read.get(name) == {cell}, '%s: table %r, subscriptions %r' % (
            name, cell, read.get(name))
    for name, cell in rows.items():  # no topic row without a QoS
        assert cell, name
