"""The layers of the package as a test (doc/architecture.md, "the folders show the layers").

Read with ``ast`` (nothing is imported):

- ``core/``, ``control/`` and ``drivers/`` import neither rclpy nor a ROS message or ROS
  package (they run and are tested without ROS);
- ``drivers/`` import nothing from ``nodes/``;
- the layers are ordered (:data:`LAYERS`): a module imports its own layer or lower ones only;
- no module imports another module's ``_private`` name, neither ``from m import _name`` nor
  ``m._name`` on an imported module.
"""
import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[2] / 'continuum_statics'
NAME = PACKAGE.name

#: Top-level modules that are ROS: rclpy and its parts, the message packages, ament tools.
ROS_MODULES = {
    'rclpy', 'rcl_interfaces', 'builtin_interfaces', 'std_msgs', 'std_srvs', 'geometry_msgs',
    'sensor_msgs', 'nav_msgs', 'visualization_msgs', 'diagnostic_msgs', 'tf2_msgs', 'tf2_ros',
    'action_msgs', 'unique_identifier_msgs', 'lifecycle_msgs', 'rosgraph_msgs', 'shape_msgs',
    'ament_index_python', 'launch', 'launch_ros', 'rosbag2_py',
    'continuum_statics_interfaces',
}
#: Layers that must run without ROS.
ROS_FREE = ('core', 'control', 'calibration', 'drivers')
#: The order of the layers: each may import its own and lower ones. The package's
#: ``__init__`` (its public entry) and ``config_paths`` (where the files are) sit with core.
LAYERS = {'': 0, 'config_paths': 0, 'core': 0, 'control': 1, 'calibration': 1, 'drivers': 1,
          'nodes': 2, 'tools': 3, '__main__': 4}

#: The floors of ``core/`` (core/__init__.py, the map), in rank order: a core module imports
#: its own floor or lower ones. ``core`` itself (the map) and the facade sit on top.
FLOORS = {'core.description': 0, 'core.rod': 1, 'core.statics': 2, 'core.estimation': 3,
          'core.dynamics': 3, 'core.robot': 4, 'core.warmup': 4, 'core': 5}

#: Imports of private names allowed: none (the last two, the kernel's section tensions and its
#: parameter layout, became kernel.section_tensions and layout.py names). Never extend it:
#: (importing module, imported module, name).
ALLOWED_PRIVATE = set()


def modules():
    """Yield (dotted name below the package, path) of every module of the package."""
    for path in sorted(PACKAGE.rglob('*.py')):
        parts = path.relative_to(PACKAGE).with_suffix('').parts
        if parts[-1] == '__init__':
            parts = parts[:-1]
        yield '.'.join(parts), path


def imports(name, path):
    """Yield (imported module below the package or top-level name, imported name or None, line).

    ``import a.b`` yields ('a.b', None); ``from a.b import c`` yields ('a.b', 'c'); attribute
    reads ``m._x`` on a module imported as ``m`` yield ('that module', '_x').
    """
    tree = ast.parse(path.read_text(), str(path))
    package = name.split('.')[:-1] if path.name != '__init__.py' else name.split('.')
    aliases = {}  # local name -> module (below the package) it binds
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                module = _below(alias.name)
                yield module, None, node.lineno
                if alias.asname:
                    aliases[alias.asname] = module
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative import
                base = package[:len(package) - node.level + 1]
                module = '.'.join(base + ([node.module] if node.module else []))
            else:
                module = _below(node.module)
            for alias in node.names:
                yield module, alias.name, node.lineno
                if module.split('.')[0] != NAME.split('.')[0]:
                    # a submodule imported from a package module: ``from core import kernel``
                    aliases[alias.asname or alias.name] = '%s.%s' % (module, alias.name)
    for node in ast.walk(tree):
        if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                and node.value.id in aliases and node.attr.startswith('_')
                and not node.attr.startswith('__')):
            yield aliases[node.value.id], node.attr, node.lineno


def _below(module):
    """Return a module of the package as its name below the package; others unchanged."""
    prefix = NAME + '.'
    return module[len(prefix):] if module.startswith(prefix) else module


def _is_package_module(module):
    return (PACKAGE / (module.replace('.', '/') + '.py')).exists() or (
        PACKAGE / module.replace('.', '/') / '__init__.py').exists()


ALL = list(modules())


@pytest.mark.parametrize('name, path', [(n, p) for n, p in ALL if n.split('.')[0] in ROS_FREE],
                         ids=lambda value: value if isinstance(value, str) else '')
def test_core_control_and_drivers_import_no_ros(name, path):
    ros = sorted({'%s (line %d)' % (module, line) for module, _, line in imports(name, path)
                  if module.split('.')[0] in ROS_MODULES})
    assert not ros, '%s imports ROS: %s' % (name, ', '.join(ros))


@pytest.mark.parametrize('name, path', [(n, p) for n, p in ALL if n.startswith('drivers')],
                         ids=lambda value: value if isinstance(value, str) else '')
def test_drivers_import_nothing_from_nodes(name, path):
    found = sorted({'%s (line %d)' % (module, line) for module, _, line in imports(name, path)
                    if module == 'nodes' or module.startswith('nodes.')})
    assert not found, '%s imports the node layer: %s' % (name, ', '.join(found))


def test_every_module_is_in_a_layer():
    assert {name.split('.')[0] for name, _ in ALL} <= set(LAYERS)


@pytest.mark.parametrize('name, path', ALL, ids=lambda value: value if isinstance(value, str)
                         else '')
def test_a_module_imports_its_own_layer_or_lower_ones(name, path):
    layer = LAYERS[name.split('.')[0]]
    above = sorted({'%s (line %d)' % (module, line) for module, _, line in imports(name, path)
                    if _is_package_module(module) and LAYERS.get(module.split('.')[0], 0) > layer})
    assert not above, '%s imports a higher layer: %s' % (name, ', '.join(above))


def floor(module):
    """Return the floor of a core module ('core.rod.kernel' -> 'core.rod'), or None."""
    parts = module.split('.')
    if parts[0] != 'core':
        return None
    return '.'.join(parts[:2]) if '.'.join(parts[:2]) in FLOORS else parts[0]


def floor_back_edges():
    """Return 'importer imports module (line)' for each import of a higher floor of core."""
    found = []
    for name, path in modules():
        if floor(name) is None:
            continue
        rank = FLOORS[floor(name)]
        found += ['%s imports %s (line %d)' % (name, module, line)
                  for module, _, line in imports(name, path)
                  if floor(module) is not None and _is_package_module(module)
                  and FLOORS[floor(module)] > rank]
    return found


def test_core_is_in_floors_and_no_floor_imports_a_higher_one():
    flat = [name for name, _ in ALL if name.startswith('core.') and floor(name) == 'core']
    assert not flat, 'core modules outside a floor (core/__init__.py lists them): %s' % flat
    assert not floor_back_edges(), '\n'.join(floor_back_edges())


def private_imports():
    """Return (importer, module, name, line) of each private name imported from elsewhere."""
    found = []
    for name, path in modules():
        for module, imported, line in imports(name, path):
            if imported is None or not imported.startswith('_') or imported.startswith('__'):
                continue
            if module == name or not _is_package_module(module):
                continue  # its own names, or a third-party module's
            found.append((name, module, imported, line))
    return found


def test_no_module_imports_another_modules_private_name():
    found = private_imports()
    unexpected = ['%s imports %s.%s (line %d)' % entry for entry in found
                  if entry[:3] not in ALLOWED_PRIVATE]
    assert not unexpected, '\n'.join(unexpected)


def test_the_allow_list_holds_only_what_is_still_there():
    # an entry fixed on main must leave the list, so that it cannot come back unnoticed
    still = {entry[:3] for entry in private_imports()}
    assert ALLOWED_PRIVATE <= still, sorted(ALLOWED_PRIVATE - still)


def test_the_checker_sees_each_kind_of_violation(tmp_path):
    # the reader itself: each rule on a module written for the test
    global PACKAGE
    package, saved = tmp_path / 'continuum_statics', PACKAGE
    (package / 'core').mkdir(parents=True)
    (package / 'drivers').mkdir()
    (package / 'nodes').mkdir()
    for folder in ('', 'core', 'drivers', 'nodes'):
        (package / folder / '__init__.py').write_text('')
    (package / 'core' / 'a.py').write_text('import numpy\nfrom rclpy.node import Node\n'
                                           '_HIDDEN = 1\n')
    (package / 'core' / 'b.py').write_text('from continuum_statics.core import a\n'
                                           'x = a._HIDDEN\n')
    (package / 'drivers' / 'd.py').write_text('from ..nodes import qos\n'
                                              'from continuum_statics.core.a import _HIDDEN\n')
    (package / 'nodes' / 'qos.py').write_text('')
    PACKAGE = package
    try:
        checked = dict(modules())
        assert [m for m, _, _ in imports('core.a', checked['core.a'])] == ['numpy', 'rclpy.node']
        assert ('core.a', '_HIDDEN') in {(m, n) for m, n, _ in imports('core.b',
                                                                        checked['core.b'])}
        drivers = {(m, n) for m, n, _ in imports('drivers.d', checked['drivers.d'])}
        assert ('nodes', 'qos') in drivers and ('core.a', '_HIDDEN') in drivers
        assert {entry[:3] for entry in private_imports()} == {
            ('core.b', 'core.a', '_HIDDEN'), ('drivers.d', 'core.a', '_HIDDEN')}
        # a back edge between floors: the rod importing statics
        for folder in ('rod', 'statics'):
            (package / 'core' / folder).mkdir()
            (package / 'core' / folder / '__init__.py').write_text('')
        (package / 'core' / 'statics' / 'bvp.py').write_text('')
        (package / 'core' / 'rod' / 'kernel.py').write_text(
            'from continuum_statics.core.statics import bvp\n')
        assert floor_back_edges() == ['core.rod.kernel imports core.statics (line 1)']
    finally:
        PACKAGE = saved


def test_every_node_module_stays_thin():
    # a node parses, calls its control object and publishes (STYLE.md): at most 350 lines
    long = {path.name: n for path in (PACKAGE / 'nodes').glob('*_node.py')
            if (n := len(path.read_text().splitlines())) > 350}
    assert not long, long
