"""Does the gradient (4.1) of seed 001 converge noise-free on random plants?

Proposition 5.2(2) (Giri, Rochdi, Chaoui), beyond the paper's Section V.C plant:
runs the study `recursive-pl-convergence` (hamjax.montecarlo.studies).
"""

import sys

from hamjax.cli.study import study_main


def main(argv: list[str] | None = None) -> int:
    return study_main("recursive-pl-convergence", argv)


if __name__ == "__main__":
    sys.exit(main())
