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
