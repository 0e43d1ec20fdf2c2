"""Which structural class the rule names (`attribute.structural_choice`): the
validation choice, unless validation cannot tell it from the best class on both
records' likelihood (estimation SSE with Akaike's 2p, plus validation SSE)."""

import jax.random as jr
import numpy as np

from hamjax.diagnosis.attribute import Z_CONFIRM, Candidate, rms, structural_choice
from hamjax.diagnosis.residuals import improvement_z


N = 2000
E = np.asarray(jr.normal(jr.key(7), (N,)))  # white noise of unit variance
S = np.sign(np.sin(2 * np.pi * np.arange(N) / 50))  # a +-1 shape the fit misses


def _cands(a: float) -> tuple[Candidate, Candidate]:
    """`A` leaves the noise; `B` the noise plus `a` times the shape (validation
    prefers A by about N a^2)."""
    r_b = E + a * S
    return (
        Candidate("A", 0, rms(E), E, None),
        Candidate("B", 1, rms(r_b), r_b, None),
    )


def _val_deficit(a: float) -> float:
    """B's validation SSE minus A's (exact, on these residuals)."""
    return float(np.sum((E + a * S) ** 2) - np.sum(E**2))


def test_a_clear_validation_lead_names_the_class_whatever_the_estimation_says():
    A, B = _cands(0.2)
    assert improvement_z(B.residual, A.residual) > Z_CONFIRM  # validation clear
    chosen, tie = structural_choice(
        [A, B], {"A": 2000.0, "B": 1000.0}, {"A": 5, "B": 5}
    )
    assert chosen is A and tie["both_records"] == "B"


def test_a_validation_tie_is_decided_by_both_records():
    A, B = _cands(0.05)
    z = improvement_z(B.residual, A.residual)
    assert 0 < z <= Z_CONFIRM  # validation prefers A, but cannot tell them apart
    d = _val_deficit(0.05)
    p = {"A": 5, "B": 5}
    # B leads on estimation by less than A leads on validation: A (the
    # estimation SSE alone, the rule before, named B)
    chosen, _ = structural_choice([A, B], {"A": 2000.0, "B": 2000.0 - 0.5 * d}, p)
    assert chosen is A
    # B leads on estimation by more: B
    chosen, tie = structural_choice([A, B], {"A": 2000.0, "B": 2000.0 - 2 * d}, p)
    assert chosen is B and tie["validation"] == "A"


def test_akaike_charges_the_parameters_fitted_on_the_estimation_record():
    # B's estimation lead exceeds its validation deficit by 1 (in units of the
    # noise variance, here s^2 = mean(E^2)); one parameter more costs 2 s^2
    A, B = _cands(0.05)
    s2 = float(np.mean(E**2))
    est = {"A": 2000.0, "B": 2000.0 - _val_deficit(0.05) - s2}
    assert structural_choice([A, B], est, {"A": 5, "B": 5})[0] is B
    assert structural_choice([A, B], est, {"A": 5, "B": 6})[0] is A


def test_agreeing_choices_record_no_tie():
    A, B = _cands(0.05)
    chosen, tie = structural_choice([A, B], {"A": 1.0, "B": 2.0}, {"A": 5, "B": 5})
    assert chosen is A and tie == {}
