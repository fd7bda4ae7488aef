"""Sphinx directive ``parameter-table``: a node's parameters as a table, from the code's tables.

``continuum_statics.nodes.parameter_tables`` (name, default, description with the unit, range,
read-only) is what the nodes declare and ``ros2 param describe`` shows; the documentation renders
the same objects, so it cannot drift from the code. ``backend-options`` does the same for a cable
backend's ``<backend>.*`` options (its ``options_spec``).
"""
from docutils import nodes
from docutils.parsers.rst import Directive


def _range(spec):
    if spec.low is None and spec.high is None:
        return ''
    low = '-inf' if spec.low is None else '%g' % spec.low
    high = 'inf' if spec.high is None else '%g' % spec.high
    return '[%s, %s]' % (low, high)


def _default(value):
    if isinstance(value, str):
        from continuum_statics.config_paths import share_dir

        share = str(share_dir()) + '/'
        if value.startswith(share):  # a default found at run time: not this machine's path
            return "'<package share>/%s'" % value[len(share):]
        return repr(value)
    return str(value)


def table(rows, header, widths):
    """Return a docutils table of text ``rows`` (the first column as literal text)."""
    group = nodes.tgroup(cols=len(header))
    for width in widths:
        group += nodes.colspec(colwidth=width)
    head = nodes.thead()
    head += _row(header, literal_first=False)
    group += head
    body = nodes.tbody()
    for row in rows:
        body += _row(row, literal_first=True)
    group += body
    result = nodes.table(classes=['parameter-table'])
    result += group
    return result


def _row(cells, literal_first):
    row = nodes.row()
    for index, text in enumerate(cells):
        entry = nodes.entry()
        paragraph = nodes.paragraph()
        if index == 0 and literal_first:
            paragraph += nodes.literal(text=text)
        else:
            paragraph += nodes.Text(text)
        entry += paragraph
        row += entry
    return row


def spec_rows(specs, prefix=''):
    """Return the table rows of ``ParamSpec`` or ``BackendOption`` objects."""
    return [[prefix + spec.name, _default(spec.default), _range(spec),
             'yes' if spec.read_only else '', spec.description] for spec in specs]


HEADER = ['parameter', 'default', 'range', 'read-only', 'meaning']
WIDTHS = [18, 10, 10, 6, 56]


class ParameterTable(Directive):
    """``parameter-table NODE``: the parameters NODE declares (statics, tip_controller, ...)."""

    required_arguments = 1

    def run(self):
        """Return the table of the node's ParamSpecs."""
        from continuum_statics.nodes import parameter_tables

        function = getattr(parameter_tables, '%s_parameters' % self.arguments[0], None)
        if function is None:
            raise self.error('no parameter table for node %r' % self.arguments[0])
        return [table(spec_rows(function()), HEADER, WIDTHS)]


class BackendOptions(Directive):
    """``backend-options NAME``: a cable backend's options, as ``NAME.option`` parameters."""

    required_arguments = 1

    def run(self):
        """Return the table of the backend's options_spec."""
        from continuum_statics.drivers import backend_class

        cls = backend_class(self.arguments[0])
        return [table(spec_rows(cls.options_spec, cls.name + '.'), HEADER, WIDTHS)]


def setup(app):
    """Register the directives."""
    app.add_directive('parameter-table', ParameterTable)
    app.add_directive('backend-options', BackendOptions)
    return {'parallel_read_safe': True, 'version': '1'}
