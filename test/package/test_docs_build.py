"""The documentation in doc/ builds with Sphinx as rosdoc2 would, with no warning.

Warnings are errors (``-W``): a broken internal link or heading anchor (MyST), a missing image, a
docstring autodoc cannot render. The node parameter tables are generated from the code's own
tables, so every parameter a node declares is on the page. The site reads offline (MathJax is
copied into it) in rosdoc2's theme.
"""
import re
import subprocess
import sys

from conftest import REPO
import pytest

pytest.importorskip('sphinx')
pytest.importorskip('myst_parser')


@pytest.fixture(scope='module')
def built(tmp_path_factory):
    out = tmp_path_factory.mktemp('doc')
    run = subprocess.run([sys.executable, '-m', 'sphinx', '-W', '--keep-going', '-q', '-b',
                          'html', str(REPO / 'doc'), str(out)], capture_output=True, text=True,
                         timeout=600)
    assert run.returncode == 0, run.stdout + run.stderr
    assert 'WARNING' not in run.stderr, run.stderr
    return out


def _text(path):
    return re.sub(r'<[^>]+>', ' ', path.read_text())


def test_every_declared_parameter_is_in_the_generated_tables(built):
    from continuum_statics.drivers import backend_class
    from continuum_statics.nodes import parameter_tables

    page = _text(built / 'parameters.html')
    names = [spec.name for node in ('statics', 'tip_controller', 'cable_driver',
                                    'tip_load_estimator')
             for spec in getattr(parameter_tables, '%s_parameters' % node)()]
    for backend in ('sim', 'dynamixel', 'canopen', 'ros2_control'):
        cls = backend_class(backend)
        names += ['%s.%s' % (cls.name, option.name) for option in cls.options_spec]
    assert str(REPO) not in page  # run-time defaults shown relative to the share
    missing = [name for name in names if name not in page]
    assert not missing, missing
    assert len(names) > 60


def test_api_reference_comes_from_the_docstrings(built):
    page = _text(built / 'api.html')
    for name in ('solve_tip_goal', 'estimate_shape', 'estimate_tip_wrench', 'CableBackend',
                 'DynamixelCableBackend', 'CanopenCableBackend'):
        assert name in page, name
    from continuum_statics.core.robot import Robot
    first_line = Robot.solve_tip_goal.__doc__.strip().splitlines()[0]
    assert ' '.join(first_line.split()[:5]) in ' '.join(page.split())


def test_every_page_is_in_the_table_of_contents(built):
    pages = {p.stem for p in (REPO / 'doc').glob('*.md')}
    assert {'install', 'first_hour', 'nodes', 'parameters', 'model', 'performance',
            'calibration', 'api'} <= pages
    for page in pages:
        assert (built / ('%s.html' % page)).is_file(), page


def test_the_site_reads_offline_in_rosdoc2s_theme(built):
    """MathJax is the site's own copy (a robot computer is often offline); rosdoc2's theme."""
    model = (built / 'model.html').read_text()
    scripts = re.findall(r'<script[^>]*\ssrc="([^"]+)"', model)
    mathjax = [src for src in scripts if 'mathjax' in src.lower()]
    assert mathjax == ['_static/mathjax/tex-chtml.js'], scripts
    assert (built / mathjax[0]).stat().st_size > 100_000
    assert list((built / '_static' / 'mathjax' / 'output' / 'chtml' / 'fonts').rglob('*.woff'))
    remote = re.compile(r'<(?:script|link|img)[^>]*\s(?:src|href)="(?:https?:)?//', re.I)
    for page in built.glob('*.html'):
        assert not remote.search(page.read_text()), page.name
    assert '_static/css/theme.css' in model and 'wy-nav-content' in model  # sphinx_rtd_theme
    assert '_static/site.css' in model and (built / '_static' / 'site.css').is_file()
    assert r'\mathbf' in model  # the TeX is there for the local MathJax to typeset
