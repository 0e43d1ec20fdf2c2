"""Does the impulse input (5.1) of seed 001 make the regressors persistently exciting?

Proposition 5.1 (Giri, Rochdi, Chaoui): runs the study `recursive-pl-excitation`
(hamjax.montecarlo.studies) for many n and level sets, vs non-exciting inputs.
"""

import sys

from hamjax.cli.study import study_main


def main(argv: list[str] | None = None) -> int:
    return study_main("recursive-pl-excitation", argv)


if __name__ == "__main__":
    sys.exit(main())
