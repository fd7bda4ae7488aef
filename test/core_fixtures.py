"""Robots built in code for the core tests (no files), from the paper's rod."""
import copy

from conftest import REPO

from continuum_statics import load_robot
from continuum_statics.core.description.robot_file import parse_robot_description
from continuum_statics.core.robot import Robot

PAPER_ROD = REPO / 'config' / 'jones2009_nitinol_rod.yaml'
TENDON_ROBOT = REPO / 'config' / 'tendon_robot.yaml'

BASE_DESCRIPTION = {
    'rod': {'length': 0.39, 'diameter': 1.56e-3, 'youngs_modulus': 54.0e9,
            'poisson_ratio': 0.3, 'density': 6800.0},
    'base': {'frame_id': 'base_link', 'position': [0.0, 0.0, 0.0],
             'orientation': [0.5, 0.5, 0.5, 0.5]},
    'gravity': [0.0, 0.0, -9.81],
    'cables': [],
    'guides': [],
}


def description(**changes):
    """Return a copy of the paper-rod mapping with top-level keys replaced."""
    data = copy.deepcopy(BASE_DESCRIPTION)
    data.update(copy.deepcopy(changes))
    return data


def make_robot(**changes):
    """Build a Robot from the paper-rod mapping with top-level keys replaced."""
    return Robot(parse_robot_description(description(**changes)))


def paper_rod():
    """Return the shipped robot file of the paper's rod."""
    return load_robot(PAPER_ROD)


def tendon_robot():
    """Return the shipped tendon robot."""
    return load_robot(TENDON_ROBOT)
