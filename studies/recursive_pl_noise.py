"""Does the seed-001 gradient estimate's error floor shrink with T under noise?

Proposition 5.2(1) (Giri, Rochdi, Chaoui): runs the study `recursive-pl-noise`
(hamjax.montecarlo.studies): error floor vs SNR and T, gradient vs batch LS.
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
    parser.add_argument("--out", default="results/recursive-pl-noise")
    args, rest = parser.parse_known_args(argv)
    return hamjax_main(
        [
            "study",
            "recursive-pl-noise",
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
