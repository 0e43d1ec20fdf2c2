"""Options shared by the refinement studies (`refinement-nbbi`, `refinement-recursive-pl`)."""

from ...refinement import RefinementOptions


def add_refinement_arguments(parser) -> None:
    """`--solver` and `--no-timing`."""
    parser.add_argument(
        "--solver", default="levenberg-marquardt", help="refinement solver"
    )
    parser.add_argument(
        "--no-timing",
        dest="timing",
        action="store_false",
        help="skip the cost measurement (two extra compilations)",
    )


def refinement_options(args) -> RefinementOptions:
    """The `RefinementOptions` chosen by `--solver`."""
    return RefinementOptions(solver=str(getattr(args, "solver", "levenberg-marquardt")))


def timing_requested(args) -> bool:
    return bool(getattr(args, "timing", True))
