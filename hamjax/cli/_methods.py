"""Per-method plug-ins of `experiment`, `identify` and `reproduce`.

A method module (e.g. `hamjax.cli.methods.recursive_pl`) defines, for each verb it
supports, `add_<verb>_arguments(parser)` and `<verb>(args) -> int | None`.
"""

from pathlib import Path

from ._common import optional_module


# verb -> {name on the command line: module}
METHODS = {
    "experiment": {
        "recursive-pl": "hamjax.cli.methods.recursive_pl",
        "nbbi": "hamjax.cli.methods.nbbi",
        "fgi": "hamjax.cli.methods.fgi",
    },
    "identify": {
        "recursive-pl": "hamjax.cli.methods.recursive_pl",
        "nbbi": "hamjax.cli.methods.nbbi",
        "fgi": "hamjax.cli.methods.fgi",
    },
    "reproduce": {
        "recursive-pl": "hamjax.cli.methods.recursive_pl",
        "backlash-frequency": "hamjax.cli.methods.backlash_frequency",
    },
}


def register_method_commands(sub, verb: str, help: str) -> None:
    parser = sub.add_parser(verb, help=help)
    methods = parser.add_subparsers(
        dest="method", metavar="METHOD", parser_class=type(parser)
    )
    methods.required = True
    for name, module in METHODS[verb].items():
        mod = optional_module(module)
        if mod is None:
            continue
        p = methods.add_parser(name, help=(mod.__doc__ or "").strip().splitlines()[0])
        getattr(mod, f"add_{verb}_arguments")(p)
        if verb == "identify":
            p.add_argument(
                "--out",
                type=Path,
                default=None,
                help="where to write result.json (default DIR/result.json)",
            )
        p.set_defaults(func=_checked(verb, getattr(mod, verb)))


def result_path(args) -> Path:
    """Where `hamjax identify` writes result.json: `--out`, or DIR/result.json."""
    out = getattr(args, "out", None)
    return Path(args.dir) / "result.json" if out is None else Path(out)


def _checked(verb: str, run):
    """`run` with its output location checked first (one line, before any work)."""
    from functools import wraps

    @wraps(run)
    def checked(args):
        from ._outputs import check_output_file, check_output_folder

        if verb == "identify":
            check_output_file(result_path(args), "--out")
        elif getattr(args, "out", None) is not None:
            check_output_folder(Path(args.out), "--out")
        return run(args)

    return checked
