"""The chi-square gates against a published table (NIST/SEMATECH e-Handbook, table 1.3.6.7.4)."""
import math

import pytest

from continuum_statics.core.estimation import gates


@pytest.mark.parametrize('probability, dof, table', [
    (0.95, 3, 7.815), (0.95, 6, 12.592), (0.999, 3, 16.266), (0.999, 6, 22.458)])
def test_quantiles_are_the_tables(probability, dof, table):
    assert gates.chi2_quantile(probability, dof) == pytest.approx(table, abs=1e-3)


def test_a_gate_sets_aside_what_lies_beyond_its_quantile_and_nothing_without_freedom():
    assert gates.gate(3, gates.LOAD_GATE_PROBABILITY) == pytest.approx(16.266, abs=1e-3)
    assert 30.5 < gates.gate(3, gates.SENSOR_GATE_PROBABILITY) < 30.8  # "the 3-dof gate of 30.7"
    assert gates.passes(16.0, 3, 1e-3) and not gates.passes(16.5, 3, 1e-3)
    assert gates.passes(1e9, 0, 1e-3)  # no degrees of freedom: nothing to judge


def test_quantiles_equal_the_closed_form_and_scipys_in_the_tails_the_gates_use():
    """Quantiles against two degrees of freedom's closed form, -2 log(1 - p), and scipy's ppf.

    scipy is an independent implementation; the package computes them without it (its import
    took 0.5-1.2 s of a node's start).
    """
    from scipy.stats import chi2

    for probability in (1e-9, 1e-3, 0.5, 0.95, 1 - 1e-3, 1 - 1e-6, 1 - 1e-9):
        assert gates.chi2_quantile(probability, 2) == pytest.approx(
            -2.0 * math.log1p(-probability), rel=1e-12)
        for dof in (1, 3, 5, 6, 9, 14, 27, 40, 250):
            assert gates.chi2_quantile(probability, dof) == pytest.approx(
                chi2.ppf(probability, dof), rel=1e-11)
    with pytest.raises(ValueError, match='probability'):
        gates.chi2_quantile(1.0, 3)
