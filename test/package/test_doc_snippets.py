"""Every Python snippet of the README and doc/ runs as written; every command names real options.

Each fenced ``python`` block is executed in a fresh namespace from the repository root (its
``config/`` files and bundled data), so a reader can paste it alone. A block that needs a
running ROS graph is marked by a comment on the line before its fence, ``% snippet:
compile-only`` (MyST) or ``<!-- snippet: compile-only -->`` (README), and is only compiled.

Each ``python -m continuum_statics COMMAND --option`` in the pages (code blocks and inline code)
must name a command of ``python -m continuum_statics --help`` and options its module parses.
"""
import ast
import re

from conftest import REPO
import pytest

PAGES = [REPO / 'README.md'] + sorted((REPO / 'doc').glob('*.md'))
MARK = re.compile(r'^(?:%|<!--)\s*snippet:\s*compile-only\b')
#: Pages whose snippets are compiled only until their owner makes them self-contained.
PENDING = set()


def snippets():
    """(page name, line, source, run) of every ```python block."""
    found = []
    for page in PAGES:
        lines = page.read_text().splitlines()
        start = None
        for number, line in enumerate(lines):
            if start is None and line.strip() == '```python':
                start = number
            elif start is not None and line.strip() == '```':
                before = [text for text in lines[:start] if text.strip()]
                marked = bool(before) and MARK.match(before[-1].strip())
                found.append((page.name, start + 1, '\n'.join(lines[start + 1:number]),
                              not marked and page.name not in PENDING))
                start = None
    return found


SNIPPETS = snippets()


def test_the_snippets_are_found_and_most_run():
    ran = [s for s in SNIPPETS if s[3]]
    assert len(SNIPPETS) >= 8 and len(ran) >= 7, [(s[0], s[1], s[3]) for s in SNIPPETS]


@pytest.mark.parametrize('page,line,source,run', SNIPPETS,
                         ids=['%s:%d' % (s[0], s[1]) for s in SNIPPETS])
def test_snippet_runs_as_written(page, line, source, run, monkeypatch):
    code = compile(source, '%s:%d' % (page, line), 'exec')
    if not run:
        pytest.skip('compile-only (%s)' % ('pending' if page in PENDING else 'marked'))
    monkeypatch.chdir(REPO)
    exec(code, {'__name__': '__snippet__'})  # noqa: S102 (the documentation's own code)


def _command_modules():
    """{command: [source files whose quoted '--options' it parses]} from __main__.py."""
    main = REPO / 'continuum_statics' / '__main__.py'
    from continuum_statics.__main__ import NODES
    modules = {}
    for node in ast.walk(ast.parse(main.read_text())):
        if not (isinstance(node, ast.If) and isinstance(node.test, ast.Compare)
                and ast.unparse(node.test.left) == 'command'
                and isinstance(node.test.comparators[0], ast.Constant)):
            continue
        imports = [n.module for n in ast.walk(ast.Module(body=node.body, type_ignores=[]))
                   if isinstance(n, ast.ImportFrom)]
        modules[node.test.comparators[0].value] = imports
    for name in NODES:
        modules[name] = ['continuum_statics.nodes.%s_node' % name]
    files = {}
    for command, imports in modules.items():
        paths = [main] + [REPO / (module.replace('.', '/') + '.py') for module in imports]
        for path in list(paths[1:]):  # and what those modules import from the package
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.ImportFrom) and (node.module or '').startswith(
                        'continuum_statics.'):
                    candidate = REPO / (node.module.replace('.', '/') + '.py')
                    if candidate.is_file():
                        paths.append(candidate)
        files[command] = paths
    return files


def test_every_documented_command_and_option_exists():
    files = _command_modules()
    assert {'solve', 'simulate', 'fusion', 'calibrate', 'doctor', 'bringup'} <= set(files)
    wrong, seen = [], 0
    for page in PAGES:
        text = page.read_text().replace('\\\n', ' ')
        for match in re.finditer(r'-m continuum_statics ([a-z_|]+)([^\n`#]*)', text):
            arguments = match.group(2).split('--ros-args')[0]
            for command in match.group(1).split('|'):
                seen += 1
                if command not in files:
                    wrong.append('%s: unknown command %s' % (page.name, command))
                    continue
                source = ''.join(path.read_text() for path in files[command])
                for option in re.findall(r'(?<![\w-])--[a-z][\w-]*', arguments):
                    if "'%s'" % option not in source:
                        wrong.append('%s: %s %s' % (page.name, command, option))
    assert seen > 30, seen
    assert not wrong, wrong


def test_the_readme_names_every_node_and_command():
    from continuum_statics.__main__ import NODES, USAGE
    readme = (REPO / 'README.md').read_text()
    commands = [name for name in re.findall(r'^  ([a-z]+)\s', USAGE, re.M) if name not in NODES]
    assert {'solve', 'simulate', 'fusion', 'doctor'} <= set(commands)
    missing = [name for name in NODES if '- **%s**:' % name not in readme]  # the node list
    missing += [name for name in commands if not re.search(r'`%s[` ]' % name, readme)]
    assert not missing, missing
    assert re.search(r'`sim/tip_pose_true`, best effort', readme)
