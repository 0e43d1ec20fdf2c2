"""Seed 000 Remark 1b: NBBI (and FGI) on straight, non-smooth, non-invertible, relay-like, crossing, superposed (static) and composed (Fig. 4b) borders.

Reproduces the claim with figures + JSON under --out (see `hamjax study nbbi-shapes --help`):

    python studies/nbbi_shapes.py --realisations 1000 --out results/nbbi-shapes
"""

import sys

from hamjax.cli.study import study_main


def main(argv: list[str] | None = None) -> int:
    return study_main("nbbi-shapes", argv)


if __name__ == "__main__":
    sys.exit(main())
