"""Configuration of the output-error refinement."""

import equinox as eqx
import optimistix as optx

from ..fitting import BatchedLevenbergMarquardt


_SOLVERS = (
    "levenberg-marquardt",
    "gauss-newton",
    "bfgs",
    "batched-levenberg-marquardt",
)


class RefinementOptions(eqx.Module):
    """How `refine` solves the output-error least-squares problem.

    **Arguments:**

    - `solver`: `"levenberg-marquardt"` (default, robust to poor starts),
      `"gauss-newton"` (fast near the optimum) or `"bfgs"` (a minimiser of
      $\\tfrac12\\|r\\|^2$, no Jacobian materialised), or
      `"batched-levenberg-marquardt"` (`fitting.BatchedLevenbergMarquardt`, the
      diagnosis's solver: cheap under `vmap`; it stops on a relative decrease of
      `rtol` at low damping and ignores `atol`, its step tolerance is fixed).
    - `rtol`, `atol`: optimistix step/value tolerances.
    - `max_steps`: step budget; exceeding it is reported as `not_converged`.
    - `annealing`: smoothing widths used in turn before the exact fit, for
      parametrisations with a non-differentiable map (seed 001 piecewise-linear).
      Relative to the input's range; ignored by the other parametrisations.
    """

    solver: str = eqx.field(static=True, default="levenberg-marquardt")
    rtol: float = eqx.field(static=True, default=1e-10)
    atol: float = eqx.field(static=True, default=1e-10)
    max_steps: int = eqx.field(static=True, default=200)
    annealing: tuple[float, ...] = eqx.field(static=True, default=(0.1, 0.03, 0.01))

    def __check_init__(self):
        if self.solver not in _SOLVERS:
            raise ValueError(
                f"unknown refinement solver {self.solver!r}; choose one of {_SOLVERS}"
            )
        if not (self.rtol > 0 and self.atol > 0):
            raise ValueError(f"rtol and atol must be > 0; got {self.rtol}, {self.atol}")
        if int(self.max_steps) != self.max_steps or self.max_steps < 1:
            raise ValueError(f"max_steps must be an integer >= 1; got {self.max_steps}")
        if any(not w > 0 for w in self.annealing):
            raise ValueError(f"annealing widths must be > 0; got {self.annealing}")

    def make_solver(self):
        """The solver object these options describe (for `fitting.least_squares`)."""
        if self.solver == "batched-levenberg-marquardt":
            return BatchedLevenbergMarquardt(rtol=self.rtol)
        if self.solver == "levenberg-marquardt":
            return optx.LevenbergMarquardt(rtol=self.rtol, atol=self.atol)
        if self.solver == "gauss-newton":
            return optx.GaussNewton(rtol=self.rtol, atol=self.atol)
        return optx.BFGS(rtol=self.rtol, atol=self.atol)
