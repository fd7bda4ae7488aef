"""A recorded run replayed through the model, the rigid registration, and error statistics.

Point arrays are (n, 3) in m; errors are model minus measured.
"""
import math

import numpy as np

from continuum_statics.core.statics.length_statics import MOTION_THRESHOLD, solve_lengths

#: Error (m, per axis) of a row whose model point is not finite: large, so a fit moves away.
FAILED_ROW_ERROR = 1.0


def replay(robot, run):
    """Replay a run row by row: model marker points (n, 3; m, robot's frame) and failed rows.

    Each row's :meth:`Robot.solve_lengths` is warm-started by the previous row's solution, as on
    the robot (friction follows each cable's motion). The second array (n,) is True where the
    solve did not converge (its best state is kept) or raised.
    """
    points, failed, _ = replay_solutions(robot, run)
    return points, failed


def replay_solutions(robot, run, starts=None):
    """:func:`replay`, also returning each row's solution (None where it raised).

    ``starts``: per-row warm starts (another robot's solutions of the same run) instead of the
    previous row: a robot a finite-difference step away then converges in a chord step or two
    per row, with each cable's direction of motion (friction) held as the start had it (a
    shifted zero offset must not read as motion).
    """
    points = np.full((len(run.lengths), 3), np.nan)
    failed = np.zeros(len(run.lengths), dtype=bool)
    solutions = [None] * len(run.lengths)
    previous = None
    for i, lengths in enumerate(run.lengths):
        held = starts is not None and starts[i] is not None
        try:
            solution = solve_lengths(robot, lengths, warm_start=starts[i] if held else previous,
                                     motion_threshold=math.inf if held else MOTION_THRESHOLD)
        except ValueError:
            failed[i] = True
            continue
        failed[i] = not solution.converged
        shape = solution.shape
        points[i] = shape.tip_position + shape.tip_rotation @ robot.tip_marker
        solutions[i] = previous = solution
    return points, failed, solutions


def kabsch(points, targets):
    """Rotation R and translation p minimising |R points + p - targets| (Kabsch, no reflection)."""
    mean_p, mean_t = points.mean(axis=0), targets.mean(axis=0)
    u, _, vt = np.linalg.svd((points - mean_p).T @ (targets - mean_t))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    rotation = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return rotation, mean_t - rotation @ mean_p


def rms(errors):
    """RMS of Euclidean point errors (n, 3) (m)."""
    return float(np.sqrt(np.mean(np.sum(errors ** 2, axis=1))))


def rms_aligned(errors):
    """RMS of point errors (n, 3) after removing their mean (m).

    From rms^2 = rms_aligned^2 + |mean|^2, so it never exceeds :func:`rms` by round-off.
    """
    return float(np.sqrt(max(rms(errors) ** 2 - np.sum(errors.mean(axis=0) ** 2), 0.0)))


def error_statistics(errors):
    """Return the summary's error figures of point errors (n, 3), m: rms, rms_aligned, mean, max.

    Rows that did not solve (non-finite) count as :data:`FAILED_ROW_ERROR` per axis.
    """
    errors = np.nan_to_num(np.asarray(errors, dtype=float), nan=FAILED_ROW_ERROR,
                           posinf=FAILED_ROW_ERROR, neginf=-FAILED_ROW_ERROR)
    norms = np.linalg.norm(errors, axis=1)
    return {'rms': rms(errors), 'rms_aligned': rms_aligned(errors), 'mean': float(norms.mean()),
            'max': float(norms.max())}
