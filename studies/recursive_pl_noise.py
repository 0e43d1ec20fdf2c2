"""Does the seed-001 gradient estimate's error floor shrink with T under noise?

Proposition 5.2(1) (Giri, Rochdi, Chaoui): runs the study `recursive-pl-noise`
(hamjax.montecarlo.studies): error floor vs SNR and T, gradient vs batch LS.
"""

import sys

from hamjax.cli.study import study_main


def main(argv: list[str] | None = None) -> int:
    return study_main("recursive-pl-noise", argv)


if __name__ == "__main__":
    sys.exit(main())
