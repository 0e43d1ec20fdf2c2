"""Per-method plug-ins of `experiment`, `identify` and `reproduce`.

A method module (e.g. `hamjax.cli.methods.recursive_pl`) defines, for each verb it
supports, `add_<verb>_arguments(parser)` and `<verb>(args) -> int | None`.
"""

import importlib


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
        try:
            mod = importlib.import_module(module)
        except ModuleNotFoundError as err:
            if err.name == module:
                continue
            raise
        p = methods.add_parser(name, help=(mod.__doc__ or "").strip().splitlines()[0])
        getattr(mod, f"add_{verb}_arguments")(p)
        p.set_defaults(func=getattr(mod, verb))
