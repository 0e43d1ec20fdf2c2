"""How close do the closed-form estimates of seed 000 (NBBI border points, Table 1) and their
output-error refinement come to the Cramér-Rao bound, over record length and SNR?

Runs the study `refinement-nbbi` (hamjax.montecarlo.studies.refinement_nbbi):
bias, std, RMSE of closed form vs refined per parameter with the CRLB on the same
axes, efficiency CRLB/MSE, refinement failure rate and cost ratio; figures + JSON.
"""

import argparse
import sys


def main(argv=None) -> int:
    import matplotlib

    matplotlib.use("Agg")
    from hamjax.cli.main import main as hamjax_main

    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--realisations", "--n-trials", type=int, default=1000)
    parser.add_argument("--out", default="results/refinement-nbbi")
    args, rest = parser.parse_known_args(argv)
    return hamjax_main(
        [
            "study",
            "refinement-nbbi",
            "--seed",
            str(args.seed),
            "--realisations",
            str(args.realisations),
            "--out",
            args.out,
            *rest,
        ]
    )


if __name__ == "__main__":
    sys.exit(main())
