"""`hamjax study NAME [...]` runs a registered Monte Carlo study; `--list` lists them."""

import argparse
import contextlib
import sys
import tempfile
from pathlib import Path

from .._errors import UserInputError
from ..papers import STUDY_PACKAGES
from ._common import add_cluster_arguments, positive_int, start_cluster


_HELP = "run a registered Monte Carlo study (--list shows them)"
# PRNG implementations a study's root key may use: counter-based, so vmap of a draw
# equals the loop (rbg and unsafe_rbg draw differently under vmap, which breaks
# "a result depends only on the seed and r"; JAX's philox keys do not compile
# when sharded over several CPU devices in jax 0.10).
KEY_IMPLS = ("threefry2x32", "threefry4x32")


def register_brief(sub) -> None:
    """The `study` entry alone, for runs of another command: finding the studies
    imports every study module (half a second)."""
    sub.add_parser("study", help=_HELP)


def register(sub) -> None:
    from ..montecarlo.registry import discover_studies

    parser = sub.add_parser(
        "study",
        help=_HELP,
        description="Run a registered Monte Carlo study. Results go to --out "
        "chunk by chunk; running again with the same --out resumes.",
    )
    parser.add_argument(
        "--list", action="store_true", help="list the registered studies and exit"
    )
    names = parser.add_subparsers(
        dest="study", metavar="NAME", parser_class=type(parser)
    )
    for study in discover_studies(STUDY_PACKAGES).values():
        p = names.add_parser(
            study.name, help=study.description, description=study.description
        )
        add_study_arguments(p, study)
    parser.set_defaults(func=run)


def add_study_arguments(parser: argparse.ArgumentParser, study) -> None:
    """The options every study takes, then the study's own."""
    parser.add_argument(
        "--realisations",
        type=positive_int,
        default=study.default_realisations,
        help=f"number of Monte Carlo realisations (default {study.default_realisations})",
    )
    parser.add_argument(
        "--chunk",
        type=positive_int,
        default=study.default_chunk,
        help="realisations per compiled call; bounds the memory "
        f"(default {study.default_chunk})",
    )
    parser.add_argument(
        "--seed", type=int, default=0, help="root random seed (default 0)"
    )
    parser.add_argument(
        "--key-impl",
        choices=KEY_IMPLS,
        default=KEY_IMPLS[0],
        help="PRNG implementation of the root key, jax.random.key(seed, impl=...); "
        "recorded in the manifest (default threefry2x32, the fastest measured "
        "with hamjax's draws)",
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=None,
        help=f"output folder (default results/{study.name})",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    add_cluster_arguments(
        parser,
        how="the realisations are sharded over every device of every process; "
        "process 0 writes --out",
    )
    if study.add_arguments is not None:
        study.add_arguments(parser)


def run(args: argparse.Namespace) -> int:
    from ..montecarlo.registry import discover_studies, get_study

    if args.list:
        studies = discover_studies(STUDY_PACKAGES)
        width = max((len(n) for n in studies), default=0)
        for name, study in studies.items():
            print(f"{name:<{width}}  {study.description}")
        return 0
    if args.study is None:
        raise UserInputError("give a study NAME (`hamjax study --list` shows them)")
    return run_study(get_study(args.study, STUDY_PACKAGES), args)


def run_study(study, args: argparse.Namespace) -> int:
    """Run `study` with parsed `args`; print where the results are."""
    from .._runtime import same_rounding_in_every_lane, split_cpu_into_devices

    if study.split_cpu:  # its batched fits shard over devices
        split_cpu_into_devices()
    if study.diagnoses:  # a case's names must not depend on its batch
        same_rounding_in_every_lane()
    import jax
    import jax.random as jr

    from .._x64 import enable_x64

    start_cluster(args)
    enable_x64()
    out = Path("results") / study.name if args.out is None else Path(args.out)
    if out.exists() and not out.is_dir():
        raise UserInputError(f"--out {out}: exists and is not a folder")
    with contextlib.ExitStack() as stack:
        if jax.process_index() == 0:
            out.mkdir(parents=True, exist_ok=True)
            study_out = out
        else:  # process 0 writes the results; the others' figures are dropped
            study_out = Path(stack.enter_context(tempfile.TemporaryDirectory()))
        summary = study.run(
            jr.key(args.seed, impl=getattr(args, "key_impl", KEY_IMPLS[0])),
            realisations=args.realisations,
            chunk=args.chunk,
            out=study_out,
            quiet=args.quiet or jax.process_index() != 0,
            args=args,
        )
    if jax.process_index() != 0:
        return 0
    print(f"study {study.name}: {args.realisations} realisations, results in {out}")
    headline = summary.get("headline") if isinstance(summary, dict) else None
    if headline:
        print(headline)
    return 0


def study_main(name: str, argv: list[str] | None = None) -> int:
    """Run the study `name` from a script or a test with the options of
    `hamjax study NAME` (`argv` without the name); 2 on a user error."""
    import matplotlib

    from ..montecarlo.registry import get_study

    matplotlib.use("Agg")
    study = get_study(name, STUDY_PACKAGES)
    parser = argparse.ArgumentParser(prog=f"{name}.py", description=study.description)
    add_study_arguments(parser, study)
    args = parser.parse_args(argv)
    args.list, args.study = False, name
    try:
        return run_study(study, args)
    except UserInputError as err:
        print(f"{name}: error: {err}", file=sys.stderr)
        return 2
