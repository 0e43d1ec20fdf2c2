"""Seed 001: recursive identification with a piecewise-linear input nonlinearity."""

from .batch_ls_3_8a import batch_least_squares as batch_least_squares
from .excitation_prop5_1 import (
    excitation_level as excitation_level,
    information_matrix as information_matrix,
)
from .levels_3_1 import check_levels as check_levels
from .normalised_gradient_4_1 import (
    gradient_step as gradient_step,
    normalised_gradient as normalised_gradient,
    normalised_gradient_batch as normalised_gradient_batch,
    normalised_gradient_convergence as normalised_gradient_convergence,
)
from .procedure import (
    RecursivePLResult as RecursivePLResult,
    identify_recursive_pl as identify_recursive_pl,
    recover_history as recover_history,
)
from .rank_one_prop3_1 import (
    first_largest as first_largest,
    rank_one_decomposition as rank_one_decomposition,
)
from .recovery_3_9_to_3_18 import (
    STRUCTURES as STRUCTURES,
    RecursivePLEstimate as RecursivePLEstimate,
    dead_zone_rule as dead_zone_rule,
    points_from_d as points_from_d,
    preload_rule as preload_rule,
    recover_parameters as recover_parameters,
    slopes_and_offsets as slopes_and_offsets,
    structure_consistent as structure_consistent,
    symmetric_rule as symmetric_rule,
)
from .reparametrisation_3_2_to_3_8 import (
    check_input_in_levels as check_input_in_levels,
    interpolating_polynomial as interpolating_polynomial,
    lagrange_basis as lagrange_basis,
    lagrange_coefficients as lagrange_coefficients,
    regressor as regressor,
    split_theta as split_theta,
    theta_star as theta_star,
)
