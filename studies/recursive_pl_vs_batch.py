"""Recursive gradient (4.1) or batch least squares: bias, variance and cost?

Seed 001 (Giri, Rochdi, Chaoui): runs the study `recursive-pl-vs-batch`
(hamjax.montecarlo.studies) on the Section V.C plant with noise.
"""

import sys

from hamjax.cli.study import study_main


def main(argv: list[str] | None = None) -> int:
    return study_main("recursive-pl-vs-batch", argv)


if __name__ == "__main__":
    sys.exit(main())
