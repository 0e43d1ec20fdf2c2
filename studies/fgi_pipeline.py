"""Seed 000 two-stage pipeline: how NBBI errors in the U_i propagate into G-hat (FGI with exact vs estimated U), over a noise-level sweep.

Reproduces the claim with figures + JSON under --out (see `hamjax study fgi-pipeline --help`):

    python studies/fgi_pipeline.py --realisations 1000 --out results/fgi-pipeline
"""

import sys

from hamjax.cli.study import study_main


def main(argv: list[str] | None = None) -> int:
    return study_main("fgi-pipeline", argv)


if __name__ == "__main__":
    sys.exit(main())
