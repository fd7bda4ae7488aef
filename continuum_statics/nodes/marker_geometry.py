"""Where to draw guide disks and cables for a solved shape (numpy only, for RViz markers)."""
import numpy as np

from continuum_statics.core.description.routing import holes_at


def nearest_nodes(s_nodes, s_values):
    """Index of the node of ``s_nodes`` (sorted, m) nearest to each of ``s_values`` (m)."""
    s_nodes = np.asarray(s_nodes, dtype=float)
    s_values = np.asarray(s_values, dtype=float)
    upper = np.clip(np.searchsorted(s_nodes, s_values), 0, len(s_nodes) - 1)
    lower = np.clip(upper - 1, 0, None)
    closer_lower = np.abs(s_nodes[lower] - s_values) < np.abs(s_nodes[upper] - s_values)
    return np.where(closer_lower, lower, upper)


def guide_and_cable_points(s_nodes, positions, rotations, guides, cable_offsets,
                           cable_ends=None):
    """Guide-disk poses and cable polylines of a shape.

    :param s_nodes: (N,) arc length of the shape's nodes, m
    :param positions: (N, 3) backbone points, m
    :param rotations: (N, 3, 3) backbone orientations, local -> global
    :param guides: (n_guides,) arc lengths of the guide disks, m
    :param cable_offsets: guide-hole offsets in the rod's local frame, m: (n_cables, 3) one per
        cable, or (n_cables, 1 + n_guides, 3) one per disk, base disk first
        (``robot.hole_offsets``, general routing)
    :param cable_ends: (n_cables,) arc length of each cable's end disk, m (its section's last
        guide); None: every cable runs to the last guide
    :returns: guide positions (n_guides, 3), guide rotations (n_guides, 3, 3) and cable points:
        the base exit point, then the hole in every guide up to the cable's end disk; an
        (n_cables, n_guides + 1, 3) array without ``cable_ends``, else a list of (k, 3) arrays
    """
    positions = np.asarray(positions, dtype=float)
    rotations = np.asarray(rotations, dtype=float)
    guides = np.asarray(guides, dtype=float)
    nodes = nearest_nodes(s_nodes, guides)
    path_nodes = np.concatenate([[0], nodes[guides > 0.0]])  # a guide at s = 0 is the base disk
    offsets = np.asarray(cable_offsets, dtype=float)
    if offsets.ndim < 3:  # one offset per cable: the same hole in every disk
        offsets = np.repeat(offsets.reshape(-1, 1, 3), len(path_nodes), axis=1)
    holes = holes_at(positions[path_nodes][None], rotations[path_nodes][None], offsets)
    if cable_ends is None:
        return positions[nodes], rotations[nodes], holes
    counts = 1 + np.searchsorted(guides[guides > 0.0], np.asarray(cable_ends, dtype=float) + 1e-9)
    return positions[nodes], rotations[nodes], [
        holes[c, :counts[c]] for c in range(offsets.shape[0])]


def section_layout(robot):
    """Per-cable end-disk arc lengths and section ends of a robot, m.

    :returns: ``cable_ends`` (n_cables,) and ``section_ends`` (n_sections,), increasing; a robot
        without sections (a passive rod) is one section ending at its length
    """
    sections = tuple(getattr(robot, 'sections', ()) or ())
    cable_ends = np.full(len(robot.cable_names), float(robot.length))
    section_ends = []
    for section in sections:
        end = getattr(section, 'end', None)
        if end is None:
            end = float(section.guides[-1]) if len(section.guides) else float(robot.length)
        section_ends.append(float(end))
        for index in section.cable_indices:
            cable_ends[index] = end
    if not section_ends:
        section_ends = [float(robot.length)]
    return cable_ends, np.asarray(section_ends)


def section_of(s_values, section_ends):
    """Index of the section each arc length (m) lies in (the last one beyond the ends)."""
    index = np.searchsorted(np.asarray(section_ends), np.asarray(s_values) - 1e-9)
    return np.minimum(index, len(section_ends) - 1)
