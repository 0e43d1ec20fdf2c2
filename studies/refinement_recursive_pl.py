"""How close do the closed-form estimates of seed 001 (batch least squares on (3.8)) and their
output-error refinement come to the Cramér-Rao bound, over record length and SNR?

Runs the study `refinement-recursive-pl` (hamjax.montecarlo.studies.refinement_recursive_pl):
bias, std, RMSE of closed form vs refined per parameter with the CRLB on the same
axes, efficiency CRLB/MSE, refinement failure rate and cost ratio; figures + JSON.
"""

import sys

from hamjax.cli.study import study_main


def main(argv: list[str] | None = None) -> int:
    return study_main("refinement-recursive-pl", argv)


if __name__ == "__main__":
    sys.exit(main())
