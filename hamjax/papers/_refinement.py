"""Options shared by the refinement studies (`refinement-nbbi`, `refinement-recursive-pl`)."""

from ..montecarlo.registry import StudyOption
from ..refinement import RefinementOptions


REFINEMENT_OPTIONS = (
    StudyOption("solver", "levenberg-marquardt", "refinement solver"),
    StudyOption(
        "timing",
        True,
        "skip the cost measurement (two extra compilations)",
        negate=True,
    ),
)


def refinement_options(opts) -> RefinementOptions:
    """The `RefinementOptions` chosen by `--solver`."""
    return RefinementOptions(solver=str(opts.solver))
