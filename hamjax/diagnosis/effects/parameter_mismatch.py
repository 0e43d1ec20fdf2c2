"""`parameter_mismatch`: the nominal structure with its own parameters re-fitted."""

from ._base import AbstractEffect


class ParameterMismatch(AbstractEffect):
    """No structural slot: only the re-fittable nominal parameters move.

    Re-fittable (the contract): the linear block's denominator (poles) and static
    gain with the numerator shape fixed; the six piecewise-linear parameters; an
    input and an output scale of a tabulated map. Every other candidate frees the
    same nominal parameters as well, so a structural effect is named only for what
    re-fitting alone cannot explain.
    """

    name = "parameter_mismatch"
