"""Proposition 1 of seed 000: NBBI border-point error against N, plain average (5) vs settled average; log-log slopes with CI (1/N transient bias vs N^-1/2 noise).

Reproduces the claim with figures + JSON under --out (see `hamjax study nbbi-rate --help`):

    python studies/nbbi_rate.py --realisations 1000 --out results/nbbi-rate
"""

import sys

from hamjax.cli.study import study_main


def main(argv: list[str] | None = None) -> int:
    return study_main("nbbi-rate", argv)


if __name__ == "__main__":
    sys.exit(main())
