"""Proposition 2 of seed 000: |G-hat_M(jk w) - G(jk w)| against the number M of averaged periods, per harmonic; log-log slopes with CI.

Reproduces the claim with figures + JSON under --out (see `hamjax study fgi-rate --help`):

    python studies/fgi_rate.py --realisations 1000 --out results/fgi-rate
"""

import sys

from hamjax.cli.study import study_main


def main(argv: list[str] | None = None) -> int:
    return study_main("fgi-rate", argv)


if __name__ == "__main__":
    sys.exit(main())
