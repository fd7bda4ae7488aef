"""Solvers as ordered lists of attempts (scipy's ``integrate/_ivp`` pattern of small methods).

An attempt is a function of one job record: it answers (a result) or passes (None), handing
its progress on through the job. A solver is its list, tried in order; the last always answers.
"""


def first_answer(attempts, job):
    """Return the answer of the first attempt in ``attempts`` that gives one for ``job``."""
    for attempt in attempts:
        answer = attempt(job)
        if answer is not None:
            return answer
    raise AssertionError('the last attempt of %s always answers' % (attempts,))  # pragma: no cover
