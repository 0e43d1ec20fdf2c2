"""The fitting layer: one least-squares interface over two solvers (optimistix's,
and a batched Levenberg-Marquardt on normal equations), one standard-error
routine, and the ahead-of-time compiled-program cache of the batched fits."""

from .compiled import CompiledPrograms as CompiledPrograms
from .information import (
    covariance_from_information as covariance_from_information,
    standard_errors_from_information as standard_errors_from_information,
)
from .least_squares import (
    BatchedLevenbergMarquardt as BatchedLevenbergMarquardt,
    GaussianPrior as GaussianPrior,
    LeastSquaresSolution as LeastSquaresSolution,
    NormalEquations as NormalEquations,
    least_squares as least_squares,
)
