"""Does the impulse input (5.1) of seed 001 make the regressors persistently exciting?

Proposition 5.1 (Giri, Rochdi, Chaoui): runs the study `recursive-pl-excitation`
(hamjax.montecarlo.studies) for many n and level sets, vs non-exciting inputs.
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
    parser.add_argument("--out", default="results/recursive-pl-excitation")
    args, rest = parser.parse_known_args(argv)
    return hamjax_main(
        [
            "study",
            "recursive-pl-excitation",
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
