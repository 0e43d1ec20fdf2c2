"""Does the gradient (4.1) of seed 001 converge noise-free on random plants?

Proposition 5.2(2) (Giri, Rochdi, Chaoui), beyond the paper's Section V.C plant:
runs the study `recursive-pl-convergence` (hamjax.montecarlo.studies).
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
    parser.add_argument("--out", default="results/recursive-pl-convergence")
    args, rest = parser.parse_known_args(argv)
    return hamjax_main(
        [
            "study",
            "recursive-pl-convergence",
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
