"""How do rho* and the initial estimate change the convergence speed of (4.1)?

Seed 001 Section IV.A (Giri, Rochdi, Chaoui): runs the study `recursive-pl-tuning`
(hamjax.montecarlo.studies) on the Section V.C plant.
"""

import sys

from hamjax.cli.study import study_main


def main(argv: list[str] | None = None) -> int:
    return study_main("recursive-pl-tuning", argv)


if __name__ == "__main__":
    sys.exit(main())
