"""The repository points only to documents and images it contains; the README is a front page."""
import re
import subprocess

from conftest import REPO
import pytest


def tracked_text_files():
    names = subprocess.run(['git', 'ls-files'], cwd=REPO, capture_output=True, text=True,
                           check=True).stdout.split()
    for name in names:
        path = REPO / name
        if path.suffix in ('.py', '.md', '.yaml', '.xml', '.txt', '.rviz', '.sh', '.csv') \
                and path.is_file():
            yield path


@pytest.mark.ros
def test_no_reference_to_a_design_document_outside_the_repository():
    offenders = [str(p.relative_to(REPO)) for p in tracked_text_files()
                 if 'ARCHITECTURE.md' in p.read_text(errors='replace')
                 and p.name != 'test_tools_docs.py']
    assert not offenders, 'ARCHITECTURE.md is not in the repository; use doc/: %s' % offenders


@pytest.mark.ros
def test_docs_references_and_readme_links_exist():
    missing = []
    for path in tracked_text_files():
        text = path.read_text(errors='replace')
        for target in set(re.findall(r'\bdoc/[\w./-]+\.(?:md|png)', text)):
            if not (REPO / target).is_file():
                missing.append('%s -> %s' % (path.relative_to(REPO), target))
    readme = (REPO / 'README.md').read_text()
    for target in re.findall(r'\]\(([^)#:]+)(?:#[^)]*)?\)', readme):
        if not (REPO / target).exists():
            missing.append('README.md -> %s' % target)
    assert not missing, missing


def test_readme_is_a_front_page_with_the_two_commands():
    readme = (REPO / 'README.md').read_text()
    assert len(readme.splitlines()) <= 200
    assert '| `make demo` |' in readme and '| `make test` |' in readme
    # the newcomer's way on: the first-hour page and the docs build
    assert '](doc/first_hour.md)' in readme and 'make docs' in readme


def test_every_doc_page_is_linked_from_the_readme():
    readme = (REPO / 'README.md').read_text()
    pages = sorted(p.name for p in (REPO / 'doc').glob('*.md') if p.name != 'index.md')
    unlinked = [page for page in pages if '](doc/%s' % page not in readme]
    assert not unlinked, unlinked
