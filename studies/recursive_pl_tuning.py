"""How do rho* and the initial estimate change the convergence speed of (4.1)?

Seed 001 Section IV.A (Giri, Rochdi, Chaoui): runs the study `recursive-pl-tuning`
(hamjax.montecarlo.studies) on the Section V.C plant.
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
    parser.add_argument("--out", default="results/recursive-pl-tuning")
    args, rest = parser.parse_known_args(argv)
    return hamjax_main(
        [
            "study",
            "recursive-pl-tuning",
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
