"""The obstacles of the clearance-goal tests and benchmark (robot file entries, SI units)."""

#: Clearance (m) the goals keep.
CLEARANCE = 0.005


def scene(length):
    """Return a shelf over the reach of a rod of ``length`` (m), a post beside it and a wall."""
    return [{'name': 'shelf', 'box': {'size': [0.12, 0.3, 0.01]},
             'position': [0.12, 0.0, 0.8 * length]},
            {'name': 'post', 'capsule': {'radius': 0.01, 'length': 0.3},
             'position': [-0.08, 0.06, 0.5 * length]},
            {'name': 'wall', 'plane': {'normal': [0.0, 1.0, 0.0], 'offset': -0.1}}]
