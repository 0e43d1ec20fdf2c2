"""`hamjax blind make|score`: the public withheld-effect benchmark."""

import argparse
import sys
from pathlib import Path

from .._errors import UserInputError
from ._common import positive_int


def register(sub) -> None:
    p = sub.add_parser(
        "blind",
        help="make or score a blind withheld-effect benchmark",
    )
    verbs = p.add_subparsers(dest="verb", metavar="VERB")
    verbs.required = True
    m = verbs.add_parser(
        "make",
        help="draw K cases into DIR/cases/<name>/ (truth in DIR/truth.json only)",
        description="Draw K gap cases into DIR/cases/<name>/ (docs/gap-case-folder.md) "
        "and their truth into DIR/truth.json. A non-empty DIR is refused unless "
        "--force, which first removes an earlier benchmark's files.",
    )
    m.add_argument("--cases", type=positive_int, required=True, metavar="K")
    m.add_argument("--seed", type=int, default=0)
    m.add_argument(
        "--realism",
        choices=("exact", "realistic"),
        default=None,
        help="family A only (default exact); families B and loops are physical by "
        "construction",
    )
    m.add_argument(
        "--family",
        choices=("A", "B", "loops"),
        default="A",
        help="A: the catalogue's formulas (papers/gap/blind.py, default); B: physical "
        "plants written independently of them (papers/gap/family_b.py, docs/family-b.md), "
        "the held-out family no constant of the diagnosis is chosen on; loops: PI "
        "control loops with and without valve stiction, OP -> PV "
        "(papers/gap/control_loops.py, docs/control-loops.md), held out as B",
    )
    m.add_argument(
        "--classes",
        choices=("fourteen", "twelve"),
        default=None,
        help="family B only: the 14 classes (default) or the 12 of its first version "
        "(no friction, no feedback nonlinearity: its sets exactly)",
    )
    m.add_argument(
        "--estimation-input",
        choices=("default", "prbs"),
        default=None,
        help="family A only: prbs makes every case's estimation input a +-1 PRBS "
        "(two levels; every other draw as in the default set, docs/family-b.md)",
    )
    m.add_argument("--out", type=Path, required=True)
    m.add_argument(
        "--force",
        action="store_true",
        help="write into a non-empty DIR (an earlier benchmark there is removed)",
    )
    m.set_defaults(func=run_make)
    s = verbs.add_parser(
        "score",
        help="score RESULTS/<case>/diagnosis.json (from `hamjax diagnose DIR/cases/* "
        "--out RESULTS`) against DIR/truth.json",
    )
    s.add_argument("dir", type=Path, metavar="DIR")
    s.add_argument("results", type=Path, metavar="RESULTS")
    s.set_defaults(func=run_score)


def _check_make_out(out: Path, force: bool) -> list[Path]:
    """The earlier benchmark files to remove; refuses a non-empty DIR without --force."""
    from ._outputs import check_output_folder, earlier_blind, is_nonempty_folder

    check_output_folder(out)
    if is_nonempty_folder(out) and not force:
        raise UserInputError(
            f"{out}: --out is not empty; add --force to write the benchmark there "
            "(an earlier benchmark's files are removed), or choose another --out"
        )
    return earlier_blind(out)


def run_make(args: argparse.Namespace) -> int:
    from ._outputs import remove_files

    if args.family != "A" and args.realism is not None:
        raise UserInputError(
            f"--realism applies to family A only (family {args.family} is physical by "
            "construction)"
        )
    if args.family != "B" and args.classes is not None:
        raise UserInputError("--classes applies to family B only")
    if args.family != "A" and args.estimation_input is not None:
        raise UserInputError("--estimation-input applies to family A only")
    earlier = _check_make_out(args.out, args.force)
    remove_files(earlier, args.out)
    if args.family == "B":
        from ..papers.gap.family_b import make_cases as make_cases_b

        truth = make_cases_b(
            args.seed, args.cases, args.out, classes=args.classes or "fourteen"
        )
        print(f"wrote {len(truth['cases'])} family-B cases to {args.out / 'cases'}")
    elif args.family == "loops":
        from ..papers.gap.control_loops import make_cases as make_cases_loops

        truth = make_cases_loops(args.seed, args.cases, args.out)
        print(f"wrote {len(truth['cases'])} control-loop cases to {args.out / 'cases'}")
    else:
        import jax.random as jr

        from ..papers.gap.blind import make_cases

        realism = args.realism or "exact"
        estimation = args.estimation_input or "default"
        truth = make_cases(
            jr.key(args.seed),
            args.cases,
            args.out,
            realism=realism,
            estimation=estimation,
        )
        kind = realism if estimation == "default" else f"{realism} PRBS-estimation"
        print(f"wrote {len(truth['cases'])} {kind} cases to {args.out / 'cases'}")
    print(f"diagnose them with: hamjax diagnose {args.out / 'cases'}/* --out RESULTS")
    return 0


def _read_truth(folder: Path) -> dict:
    """DIR/truth.json, checked to list cases with their effect and noise std."""
    from ..io import read_json

    path = Path(folder) / "truth.json"
    if not path.is_file():
        raise UserInputError(
            f"{path}: not found (is {folder} a blind-benchmark folder?)"
        )
    truth = read_json(path)
    cases = truth.get("cases")
    if not isinstance(cases, dict) or not cases:
        raise UserInputError(f"{path}: no cases listed (key 'cases')")
    for name, tr in cases.items():
        if not (isinstance(tr, dict) and {"effect", "noise_std"} <= set(tr)):
            raise UserInputError(f"{path}: case {name} lacks 'effect' or 'noise_std'")
    return truth


def _result_path(results: Path, name: str, n_cases: int) -> Path:
    """Where `hamjax diagnose` put case `name`: RESULTS/<name>/diagnosis.json, or
    RESULTS/diagnosis.json when the benchmark has a single case."""
    per_case = results / name / "diagnosis.json"
    if n_cases == 1 and not per_case.is_file():
        return results / "diagnosis.json"
    return per_case


def _read_result(path: Path) -> tuple[str, tuple[float, float], float | None]:
    """The effect named in a diagnosis.json, its gaps before and after, and the
    probability it gives the named effect (None without `probabilities`)."""
    from ..io import read_json

    r = read_json(path)
    gaps = (r.get("gap_before"), r.get("gap_after"))
    if not isinstance(r.get("effect"), str) or not all(
        isinstance(g, int | float) and not isinstance(g, bool) for g in gaps
    ):
        raise UserInputError(
            f"{path}: not a diagnosis (needs 'effect', 'gap_before', 'gap_after')"
        )
    probs = r.get("probabilities")
    conf = float(probs.get(r["effect"], 0.0)) if isinstance(probs, dict) else None
    return r["effect"], (float(gaps[0]), float(gaps[1])), conf


def read_results(folder: Path, results: Path) -> tuple[dict, dict, dict, dict]:
    """`(truth, named, shrinks, confidences)` for `papers.gap.blind.score`; refuses
    RESULTS without any result, and warns on stderr how many cases have none."""
    truth = _read_truth(folder)
    if not Path(results).is_dir():
        raise UserInputError(f"{results}: results folder not found")
    names = list(truth["cases"])
    named, shrinks, confidences = {}, {}, {}
    for name in names:
        path = _result_path(Path(results), name, len(names))
        if path.is_file():
            named[name], shrinks[name], conf = _read_result(path)
            if conf is not None:
                confidences[name] = conf
    missing = [n for n in names if n not in named]
    if not named:
        raise UserInputError(
            f"{results}: no diagnosis.json for any of the {len(names)} cases of "
            f"{Path(folder) / 'truth.json'} (run `hamjax diagnose "
            f"{Path(folder) / 'cases'}/* --out {results}` first)"
        )
    if missing:
        shown = ", ".join(missing[:5]) + (", ..." if len(missing) > 5 else "")
        print(
            f"hamjax: warning: {results}: {len(missing)} of {len(names)} cases have "
            f"no diagnosis.json ({shown}); scoring the other {len(named)}",
            file=sys.stderr,
        )
    return truth, named, shrinks, confidences


def run_score(args: argparse.Namespace) -> int:
    from ..io import write_json
    from ..papers.gap.blind import format_score, score
    from ._outputs import check_output_file

    check_output_file(args.results / "score.json", "RESULTS/score.json")
    truth, named, shrinks, confidences = read_results(args.dir, args.results)
    s = score(truth, named, shrinks, confidences)
    print(format_score(s))
    write_json(args.results / "score.json", s)
    if s.get("calibration"):
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from ..plotting.diagnosis import plot_reliability

        fig = plot_reliability(s["calibration"])
        fig.tight_layout()
        fig.savefig(args.results / "reliability.png", dpi=110)
        plt.close(fig)
    return 0
