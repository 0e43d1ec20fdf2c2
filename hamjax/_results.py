"""Result codes shared by the estimators (lineax/optimistix style)."""

import equinox as eqx


class RESULTS(eqx.Enumeration):
    """Outcome of an identification or refinement; failures are values under vmap."""

    successful = ""
    nonfinite = "The estimate contains NaN or inf (data too noisy or not exciting)."
    not_converged = "The iterative solver did not converge within its step budget."
    inconsistent_structure = (
        "The estimates are inconsistent with the named nonlinearity structure."
    )
    not_exciting = "The input does not excite the quantities to be identified."
    cycle_not_rebuilt = (
        "FGI cannot rebuild the periodic backlash output u from the NBBI points: the "
        "input reverses before the output reaches a border whose value at that level "
        "the first cycle did not show (seed 000 Table 2 needs u; try other levels)."
    )
    degenerate = (
        "The output record is constant to rounding: it carries no response to "
        "identify (a dead sensor?)."
    )
    constrained = (
        "The estimate lies on the projection ball of radius rho*: rho* is below the "
        "parameter norm, so (4.1) cannot reach the parameters (raise --rho)."
    )


def result_name(code) -> str:
    """The name of a concrete `RESULTS` item (`"successful"`, `"degenerate"`, ...)."""
    value = int(code._value)
    for name, item in RESULTS._name_to_item.items():
        if int(item._value) == value:
            return name
    raise ValueError(f"not a RESULTS code: {value}")
