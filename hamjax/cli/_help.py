"""Conventions every subcommand follows, applied to the whole parser tree once it is
built: `--quiet`/`--verbose` (also accepted after the subcommand) and a `--help`
that ends with an example."""

import argparse


# command path (as typed after `hamjax`) -> the example shown by its --help. A
# path missing here uses its parent's example with its own name put for NAME.
EXAMPLES = {
    "": "hamjax diagnose rig/case1 --out results\n"
    "hamjax experiment nbbi --levels=-1,-0.5,0,0.5,1 --hold 40 --dt 0.01 --out nbbi",
    "demo": "hamjax demo --out hamjax-demo",
    "simulate": "hamjax simulate model.json --input exp/input.csv --noise-std 0.01 "
    "--out exp/data.csv",
    "experiment": "hamjax experiment nbbi --levels=-1,-0.5,0,0.5,1 --hold 40 "
    "--dt 0.01 --out nbbi",
    "experiment recursive-pl": "hamjax experiment recursive-pl --levels=-6,-3,3,6 "
    "--order 2 --periods 2000 --dt 1 --out rpl",
    "experiment nbbi": "hamjax experiment nbbi --levels=-1,-0.5,0,0.5,1 --hold 40 "
    "--dt 0.01 --out nbbi",
    "experiment fgi": "hamjax experiment fgi --nbbi nbbi --omega 1.0 --periods 20 "
    "--dt 0.01 --out fgi",
    "identify": "hamjax identify nbbi nbbi --refine     # reads nbbi/data.csv",
    "identify recursive-pl": "hamjax identify recursive-pl rpl --structure dead-zone",
    "identify nbbi": "hamjax identify nbbi nbbi --settled",
    "identify fgi": "hamjax identify fgi fgi",
    "reproduce": "hamjax reproduce recursive-pl --out rpl-paper",
    "reproduce recursive-pl": "hamjax reproduce recursive-pl --out rpl-paper",
    "reproduce backlash-frequency": "hamjax reproduce backlash-frequency "
    "--out bf-paper --seed 1",
    "study": "hamjax study --list\nhamjax study NAME --realisations 20 --out results/NAME",
    "study NAME": "hamjax study NAME --realisations 20 --out results/NAME",
    "diagnose": "hamjax diagnose rig/case1 --out results            "
    "# results/diagnosis.json\n"
    "hamjax diagnose cases/* --out results --figures    "
    "# results/<case>/diagnosis.json\n"
    "hamjax diagnose cases/* --out results --force      # replace earlier results",
    "blind": "hamjax blind make --cases 20 --seed 1 --out bench\n"
    "hamjax diagnose bench/cases/* --out bench-results\n"
    "hamjax blind score bench bench-results",
    "blind make": "hamjax blind make --cases 20 --seed 1 --out bench",
    "blind score": "hamjax blind score bench bench-results   "
    "# writes bench-results/score.json",
}


class HelpFormatter(argparse.HelpFormatter):
    """argparse's formatter, except that an epilog starting with `example` keeps
    its lines (descriptions are still wrapped)."""

    def _fill_text(self, text, width, indent):
        if text.startswith("example"):
            return "".join(indent + line for line in text.splitlines(keepends=True))
        return super()._fill_text(text, width, indent)


def example(path: str) -> str | None:
    """The `--help` example of the command `path` ("" for `hamjax` itself)."""
    if path in EXAMPLES:
        text = EXAMPLES[path]
    else:
        parent, _, name = path.rpartition(" ")
        generic = EXAMPLES.get(f"{parent} NAME".strip())
        if generic is None:
            return None
        text = generic.replace("NAME", name)
    lines = text.splitlines()
    return "example:\n" + "".join(f"  {ln}\n" for ln in lines)


def add_verbosity(parser: argparse.ArgumentParser, default) -> None:
    """`-q/--quiet` and `-v/--verbose` (exclusive), unless `parser` has its own."""
    have = parser._option_string_actions
    if "--quiet" in have or "--verbose" in have:
        return
    group = parser.add_mutually_exclusive_group()
    group.add_argument(
        "-q",
        "--quiet",
        action="store_true",
        default=default,
        help="print nothing but errors and warnings",
    )
    group.add_argument(
        "-v",
        "--verbose",
        action="store_true",
        default=default,
        help="print more detail (and a traceback for unexpected errors)",
    )


def _subparsers(parser: argparse.ArgumentParser):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            yield from action.choices.items()


def apply_conventions(parser: argparse.ArgumentParser, path: str = "") -> None:
    """Give `parser` and every subcommand below it the verbosity options (the
    subcommands' without a default, so that `hamjax --quiet CMD` stays quiet) and
    the example epilog."""
    add_verbosity(parser, False if path == "" else argparse.SUPPRESS)
    parser.formatter_class = HelpFormatter
    if parser.epilog is None:
        parser.epilog = example(path)
    for name, sub in _subparsers(parser):
        apply_conventions(sub, f"{path} {name}".strip())
