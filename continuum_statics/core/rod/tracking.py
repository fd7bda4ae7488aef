"""Compiled solves of the shape estimator: the warm-started one a node runs every cycle, and cold.

The same constrained Gauss-Newton as :func:`least_squares.constrained_gauss_newton` (lengths in
the least-squares sense, the tip moment balance exactly, second-order correction), but on the
Jacobians of the previous estimate, corrected by Broyden updates instead of recomputed: one model
run per iteration, and no Python between them. When a step fails on those Jacobians they are
refreshed once by finite differences at the current state: on lengths no shape fits exactly (real
encoders) the minimum has a nonzero residual, where a secant Jacobian's step points nowhere
useful, and only the model's own Jacobian tells that the fit is stationary. Secant Jacobians not
trusted any more (over :data:`SECANT_AGE` updates, or a cold estimate's) are refreshed at the
start of the call instead. The work of one call is bounded (``max_runs`` IVPs): a call that would
need more returns its best state (``ok`` False), and so does a budgeted call that refreshed its
Jacobians after a failed step (the next measurement steps on them). A cold estimate starts on
the passive rod's Jacobians (``estimation``); the fallback of an estimate solved to the end runs
the same loop with finite-difference Jacobians at every evaluation (one compiled call instead of
a Python loop over the kernels), then :func:`least_squares.constrained_gauss_newton` from where
it stopped.
"""
from typing import NamedTuple

import numba
import numpy as np

from continuum_statics.core.description.layout import LENGTH_ROWS_AT
from continuum_statics.core.rod.kernel import probe
from continuum_statics.core.rod.least_squares import constrained_step

#: Levenberg-Marquardt damping a solve starts with (relative to the normal matrix's diagonal).
DAMPING = 1e-6
_NONE = np.zeros(0)
_NO_STATES = np.zeros((0, 0))


class WarmStart(NamedTuple):
    """What an estimate hands the next one (``ShapeEstimate.jacobians``)."""

    jac: np.ndarray  #: (n_cables, state size) d lengths / d x at the estimate (m per unit x)
    con_jac: np.ndarray  #: (3, state size) d balance / d x
    damping: float = DAMPING  #: the damping reached (a capped estimate's step size goes on)
    values: np.ndarray = _NONE  #: (n_cables + 3,) model lengths (m) and balance at the state
    states: np.ndarray = _NO_STATES  #: (N, 21) node states there (writable: a numba argument)
    load: np.ndarray = _NONE  #: (6,) the tip force and moment ``values`` hold for
    age: int = 0  #: secant updates of ``jac`` since it was the model's own


class TrackStart(NamedTuple):
    """Where :func:`track` starts: a state and what the call before knew there."""

    x: np.ndarray  #: solver state
    jac: np.ndarray  #: as :class:`WarmStart`; empty (0, 0): finite differences at every step
    con_jac: np.ndarray
    damping: float
    values: np.ndarray  #: empty: integrate the model at ``x`` first
    states: np.ndarray
    age: int


#: Iterations of a warm-started estimate (one IVP each when the steps succeed).
TRACK_ITERATIONS = 6
#: IVPs a node's warm-started estimate may integrate per measurement by default (statics'
#: ``max_model_runs``): its iterations, line searches and Jacobian refreshes (``probe_runs``
#: IVPs each, the last of which may overrun it); 8-25 us each on the example robots.
TRACK_RUNS = 24
#: A step the model's own (finite-difference) Jacobian predicts to change the lengths by less than
#: this fraction of the misfit is taken as stationary: the size of the Jacobian's own error.
STATIONARY_FRACTION = 1e-4
#: With a per-call budget (a node tracking the robot: the next measurement goes on from here), a
#: secant step predicted to change the lengths by less than this fraction of the misfit ends the
#: call: a secant Jacobian is ~1 % off, so closer is not known without the model's own (a
#: refresh, probe_runs IVPs), and the remainder is far below what the misfit (noise) moves.
SECANT_FRACTION = 1e-2
#: Secant updates after which a Jacobian is no longer trusted for that test (refreshed instead).
SECANT_AGE = 200


class TrackLimits(NamedTuple):
    """How far one :func:`track` call may go."""

    tolerance: float  #: stop when the predicted change of the lengths is below this (m)
    weight: float  #: tip balance -> length units in the merit function (m)
    max_iterations: int  #: iterations before giving up (``ok`` False)
    probe_runs: int  #: IVPs of one finite-difference Jacobian (``Robot.probe_runs``)
    #: IVPs before giving up with the best state reached (``ok`` False); a model evaluation or
    #: Jacobian refresh begun inside it may overrun it by ``probe_runs``
    max_runs: int
    secant_fraction: float  #: 0, or the :data:`SECANT_FRACTION` test of a budgeted call


class Tracked(NamedTuple):
    """What :func:`track` returns."""

    x: np.ndarray  #: the state reached
    residual: np.ndarray  #: (n_cables,) model minus measured lengths there (m)
    balance: np.ndarray  #: (3,) tip balance there
    states: np.ndarray  #: (N, 21) node states there
    jac: np.ndarray  #: (n_cables, state size) d lengths / d x, the model's own or secant
    con_jac: np.ndarray  #: (3, state size) d balance / d x
    iterations: int
    runs: int  #: IVPs integrated
    ok: bool  #: converged (else the best state reached)
    damping: float  #: the damping reached
    age: int  #: secant updates of ``jac`` since it was the model's own


@numba.njit(cache=True, nogil=True)
def _evaluate(problem, x, measured, n_free):
    """Length residual (m), tip balance, states and their Jacobians (``n_free`` columns).

    ``problem`` = (model, tip force, tip moment, fixed tensions), as :func:`track` takes them.
    """
    model, tip_force, tip_moment, fixed = problem
    probed = probe(model, tip_force, tip_moment, fixed, x, n_free)
    values, jacobian = probed.values, probed.jacobian
    lengths = LENGTH_ROWS_AT
    balance = LENGTH_ROWS_AT + measured.shape[0]
    return (values[lengths:balance] - measured, values[balance:balance + 3].copy(),
            probed.states, np.ascontiguousarray(jacobian[lengths:balance]),
            np.ascontiguousarray(jacobian[balance:balance + 3]))


@numba.njit(cache=True, nogil=True)
def track(model, tip_force, tip_moment, fixed, measured, warm, limits):
    """Estimate from ``warm``'s state; returns a :class:`Tracked`.

    :param model: the robot's :class:`~continuum_statics.core.description.layout.KernelModel`
    :param fixed: (n_cables,) fixed tensions (N)
    :param measured: (n_cables,) measured lengths (m)
    :param warm: a :class:`TrackStart`: the start state ``x``; ``jac``, ``con_jac`` its
        Jacobians (lengths, balance), Broyden-updated (one IVP per evaluation); empty (0 rows):
        finite-difference Jacobians at every evaluation instead (the cold estimate,
        ``probe_runs`` IVPs per evaluation); ``values`` (n_cables + 3,) model lengths and
        balance at ``x`` (with ``states`` its node states) when known from the call before (a
        warm start under the same tip load): the first IVP is then saved; empty: integrate it;
        ``age`` secant updates ``jac`` has had since it was the model's own (returned
        updated); ``damping`` the Levenberg-Marquardt damping to start with (a capped call's,
        returned, lets the next call go on with the step size it had reached)
    :param limits: a :class:`TrackLimits`
    """
    x0, jac0, con_jac0, damping0 = warm.x, warm.jac, warm.con_jac, warm.damping
    values0, states0, age0 = warm.values, warm.states, warm.age
    tolerance, weight, max_iterations = limits.tolerance, limits.weight, limits.max_iterations
    probe_runs, max_runs, secant_fraction = (limits.probe_runs, limits.max_runs,
                                             limits.secant_fraction)
    problem = (model, tip_force, tip_moment, fixed)
    fresh = jac0.shape[0] == 0 and con_jac0.shape[0] == 0  # the model's own Jacobians
    # secant Jacobians no longer trusted (a cold estimate's, or too many updates): the
    # model's own first; a try on them costs more than it saves
    stale = not fresh and age0 > SECANT_AGE
    n_all = x0.shape[0]
    x = x0.copy()
    if values0.shape[0] > 0 and not fresh and not stale:
        n = measured.shape[0]
        res = values0[:n] - measured
        con = values0[n:].copy()
        states = states0.copy()  # the caller's stays writable (a Shape of it would not be)
        jac, con_jac = jac0.copy(), con_jac0.copy()
        runs = 0
    elif stale:
        res, con, states, jac, con_jac = _evaluate(problem, x, measured, n_all)
        runs = probe_runs
    else:
        res, con, states, jac, con_jac = _evaluate(problem, x, measured,
                                                   n_all if fresh else 0)
        runs = probe_runs if fresh else 1
        if not fresh:
            jac, con_jac = jac0.copy(), con_jac0.copy()
    # jac, con_jac are the model's own at x (not Broyden-updated): made here, or handed on by
    # a call that made them at x0 (age 0)
    exact = fresh or stale or age0 == 0
    refreshed = stale  # the model's own Jacobians were made once in this call
    failed_secant = False  # ... because a step failed on secant ones
    age = 0 if fresh or stale else age0
    penalty = (1e3 * weight) ** 2
    current = res @ res + penalty * (con @ con)
    damping = damping0
    no_residual = np.zeros(0)
    no_jacobian = np.zeros((0, x.shape[0]))
    iteration = 0
    limit = max_iterations
    while True:
        step, predicted = constrained_step(res, jac, con, con_jac, damping)
        small = tolerance ** 2
        if exact:
            small = max(small, STATIONARY_FRACTION ** 2 * (res @ res))
        if exact or age <= SECANT_AGE:  # a budgeted call: 1 % of the misfit is near enough
            small = max(small, secant_fraction ** 2 * (res @ res))
        done = predicted @ predicted <= small and weight ** 2 * (con @ con) <= tolerance ** 2
        # without a budget, a secant Jacobian's "done" on a misfit (lengths no shape fits) is
        # confirmed by the model's own: it is ~1 % off, the step it predicts too
        trusted = (exact or secant_fraction > 0.0
                   or STATIONARY_FRACTION ** 2 * (res @ res) <= tolerance ** 2)
        if done and trusted:
            return Tracked(x, res, con, states, jac, con_jac, max(iteration, 1), runs, True,
                           damping, age)
        if failed_secant and secant_fraction > 0.0:
            # a budgeted call that needed the model's own Jacobians ends with them: the next
            # measurement steps on them (their damped tries here doubled the slowest 1 % of
            # calls: 20-21 IVPs instead of 13 on the 3-section distributed robot)
            return Tracked(x, res, con, states, jac, con_jac, iteration, runs, False, damping,
                           age)
        refresh = iteration >= limit
        if not refresh:
            iteration += 1
            accepted = False
            with_jacobian = False  # whether t_jac, t_con_jac are the model's own at the trial
            # a secant Jacobian gets one try (its damped steps rarely help): then the model's
            # own; with those, the first try comes with its Jacobians (the usual accepted
            # step), damped ones and corrections with one IVP each
            for attempt in range(0 if done else 12 if fresh or refreshed or exact else 1):
                if runs >= max_runs:
                    break
                trial = x + step
                with_jacobian = fresh and attempt == 0
                t_res, t_con, t_states, t_jac, t_con_jac = _evaluate(
                    problem, trial, measured, n_all if with_jacobian else 0)
                runs += probe_runs if with_jacobian else 1
                t_merit = t_res @ t_res + penalty * (t_con @ t_con)
                if not (np.isfinite(t_merit) and t_merit < current):
                    # second-order correction by chord iterations back onto the tip balance
                    c_trial, c_con = trial, t_con
                    for _ in range(3):
                        if runs >= max_runs:
                            break
                        correction, _ = constrained_step(no_residual, no_jacobian, c_con,
                                                         con_jac, 0.0)
                        c_trial = c_trial + correction
                        c_res, c_con, c_states, c_jac, c_jac_con = _evaluate(
                            problem, c_trial, measured, np.int64(0))  # not Literal[int]
                        runs += 1
                        c_merit = c_res @ c_res + penalty * (c_con @ c_con)
                        if np.isfinite(c_merit) and c_merit < current:
                            trial, t_res, t_con, t_states, t_merit = (c_trial, c_res, c_con,
                                                                       c_states, c_merit)
                            with_jacobian = False
                            break
                if np.isfinite(t_merit) and t_merit < current:
                    accepted = True
                    break
                damping *= 8.0
                step, predicted = constrained_step(res, jac, con, con_jac, damping)
            refresh = not accepted
        if refresh:
            # out of iterations, or no step lowers the misfit: with secant Jacobians, go on with
            # the model's own from x (they alone tell a stationary nonzero misfit); else, or
            # when the budget is spent, the caller goes on from here (the next measurement)
            if fresh or refreshed or exact or runs >= max_runs:
                return Tracked(x, res, con, states, jac, con_jac, iteration, runs, False, damping,
                           age)
            # (the refresh may overrun the budget: the next call must start on good Jacobians)
            res, con, states, jac, con_jac = _evaluate(problem, x, measured, n_all)
            runs += probe_runs
            # a call solved to the end goes on with damped tries and secant updates of them (its
            # caller falls back on the model's own Jacobians at every step if this gives up)
            exact = refreshed = failed_secant = True
            age = 0
            limit = iteration + max_iterations
            continue
        exact = with_jacobian or (fresh and runs < max_runs)
        if with_jacobian:
            jac, con_jac = t_jac, t_con_jac
        elif exact:
            _, _, _, jac, con_jac = _evaluate(problem, trial, measured, n_all)
            runs += probe_runs
        else:  # Broyden: the secant condition J dx = df for both row blocks
            age += 1
            dx = trial - x
            scale = 1.0 / (dx @ dx)
            jac += np.outer(t_res - res - jac @ dx, dx) * scale
            con_jac += np.outer(t_con - con - con_jac @ dx, dx) * scale
        x, res, con, states, current = trial, t_res, t_con, t_states, t_merit
        damping = max(damping / 4.0, 1e-9)
