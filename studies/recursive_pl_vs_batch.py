"""Recursive gradient (4.1) or batch least squares: bias, variance and cost?

Seed 001 (Giri, Rochdi, Chaoui): runs the study `recursive-pl-vs-batch`
(hamjax.montecarlo.studies) on the Section V.C plant with noise.
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
    parser.add_argument("--out", default="results/recursive-pl-vs-batch")
    args, rest = parser.parse_known_args(argv)
    return hamjax_main(
        [
            "study",
            "recursive-pl-vs-batch",
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
