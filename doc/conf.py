"""Sphinx configuration of the package documentation (what rosdoc2 builds from doc/).

``make docs`` builds it into ``build/doc`` with warnings as errors; MyST reads the Markdown pages,
autodoc the API reference from the docstrings, and ``_ext/parameter_tables.py`` renders each
node's parameters from the code's own tables. The look is rosdoc2's (``sphinx_rtd_theme``: long
code lines scroll), and MathJax is served from the built site itself (``sphinx-mathjax-offline``,
MathJax 3.2.2 copied into ``_static/mathjax``), so the equations render on an offline robot
computer. Both are pinned in requirements.txt; without them (a bare rosdoc2 run) the build falls
back to alabaster and MathJax from its CDN.
"""
from importlib.util import find_spec
from pathlib import Path
import sys

DOC = Path(__file__).resolve().parent
sys.path.insert(0, str(DOC / '_ext'))
sys.path.insert(0, str(DOC.parent))

project = 'continuum_statics'
author = 'continuum_statics maintainers'
copyright = '2026, continuum_statics maintainers'  # noqa: A001 (Sphinx's name)
extensions = [
    'myst_parser',
    'sphinx.ext.autodoc',
    'sphinx.ext.mathjax',
    'sphinx.ext.napoleon',
    'sphinx.ext.viewcode',
    'parameter_tables',
]
if find_spec('sphinx-mathjax-offline'):  # the package's name has dashes; it sets mathjax_path
    extensions.append('sphinx-mathjax-offline')
source_suffix = {'.md': 'markdown'}
root_doc = 'index'
exclude_patterns = ['_build']
myst_enable_extensions = ['dollarmath', 'colon_fence', 'deflist']
# GitHub-style anchors for `page.md#a-heading` links, checked by the build
myst_heading_anchors = 4
autodoc_member_order = 'bysource'
autodoc_default_options = {'members': True, 'show-inheritance': True}
autodoc_typehints = 'none'
html_theme = 'sphinx_rtd_theme' if find_spec('sphinx_rtd_theme') else 'alabaster'
html_static_path = ['_ext/site.css']  # table cells wrap (the theme keeps them on one line)
html_css_files = ['site.css']
html_title = 'continuum_statics'
