"""`hamjax blind make|score`: the public withheld-effect benchmark."""

import argparse
from pathlib import Path

from ._common import positive_int


def register(sub) -> None:
    p = sub.add_parser("blind", help="make or score a blind withheld-effect benchmark")
    verbs = p.add_subparsers(dest="verb", metavar="VERB")
    verbs.required = True
    m = verbs.add_parser(
        "make",
        help="draw K cases into DIR/cases/<name>/ (truth in DIR/truth.json only)",
    )
    m.add_argument("--cases", type=positive_int, required=True, metavar="K")
    m.add_argument("--seed", type=int, default=0)
    m.add_argument("--realism", choices=("exact", "realistic"), default="exact")
    m.add_argument("--out", type=Path, required=True)
    m.set_defaults(func=run_make)
    s = verbs.add_parser(
        "score",
        help="score RESULTS/<case>/diagnosis.json (from `hamjax diagnose DIR/cases/* "
        "--out RESULTS`) against DIR/truth.json",
    )
    s.add_argument("dir", type=Path, metavar="DIR")
    s.add_argument("results", type=Path, metavar="RESULTS")
    s.set_defaults(func=run_score)


def run_make(args: argparse.Namespace) -> int:
    import jax.random as jr

    from ..papers.gap.blind import make_cases

    truth = make_cases(jr.key(args.seed), args.cases, args.out, realism=args.realism)
    print(f"wrote {len(truth['cases'])} {args.realism} cases to {args.out / 'cases'}")
    print(f"diagnose them with: hamjax diagnose {args.out / 'cases'}/* --out RESULTS")
    return 0


def run_score(args: argparse.Namespace) -> int:
    from ..io import write_json
    from ..papers.gap.blind import format_score, score_folder

    s = score_folder(args.dir, args.results)
    print(format_score(s))
    write_json(args.results / "score.json", s)
    return 0
