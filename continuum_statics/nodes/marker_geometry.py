"""Where to draw guide disks and cables for a solved shape (numpy only, for RViz markers)."""
import numpy as np


def nearest_nodes(s_nodes, s_values):
    """Index of the node of ``s_nodes`` (sorted, m) nearest to each of ``s_values`` (m)."""
    s_nodes = np.asarray(s_nodes, dtype=float)
    s_values = np.asarray(s_values, dtype=float)
    upper = np.clip(np.searchsorted(s_nodes, s_values), 0, len(s_nodes) - 1)
    lower = np.clip(upper - 1, 0, None)
    closer_lower = np.abs(s_nodes[lower] - s_values) < np.abs(s_nodes[upper] - s_values)
    return np.where(closer_lower, lower, upper)


def guide_and_cable_points(s_nodes, positions, rotations, guides, cable_offsets):
    """Guide-disk poses and cable polylines of a shape.

    :param s_nodes: (N,) arc length of the shape's nodes, m
    :param positions: (N, 3) backbone points, m
    :param rotations: (N, 3, 3) backbone orientations, local -> global
    :param guides: (n_guides,) arc lengths of the guide disks, m
    :param cable_offsets: (n_cables, 3) guide-hole offsets in the rod's local frame, m
    :returns: guide positions (n_guides, 3), guide rotations (n_guides, 3, 3) and cable points
        (n_cables, n_guides + 1, 3): the base exit point, then the hole in every guide
    """
    positions = np.asarray(positions, dtype=float)
    rotations = np.asarray(rotations, dtype=float)
    offsets = np.asarray(cable_offsets, dtype=float).reshape(-1, 3)
    nodes = nearest_nodes(s_nodes, guides)
    path_nodes = np.concatenate([[0], nodes])
    holes = positions[path_nodes][None, :, :] + np.einsum(
        'kij,cj->cki', rotations[path_nodes], offsets)
    return positions[nodes], rotations[nodes], holes
