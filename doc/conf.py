"""Sphinx configuration of the package documentation (what rosdoc2 builds from doc/).

``make docs`` builds it into ``build/doc`` with warnings as errors; MyST reads the Markdown pages,
autodoc the API reference from the docstrings, and ``_ext/parameter_tables.py`` renders each
node's parameters from the code's own tables.
"""
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
source_suffix = {'.md': 'markdown'}
root_doc = 'index'
exclude_patterns = ['_build']
myst_enable_extensions = ['dollarmath', 'colon_fence', 'deflist']
# GitHub-style anchors for `page.md#a-heading` links, checked by the build
myst_heading_anchors = 4
autodoc_member_order = 'bysource'
autodoc_default_options = {'members': True, 'show-inheritance': True}
autodoc_typehints = 'none'
html_theme = 'alabaster'
html_title = 'continuum_statics'
