"""The `hamjax` command: subcommands are registered by the modules in `_COMMANDS`."""

import argparse
import importlib
import sys
import time
import traceback


# name -> module that defines `register(subparsers)`; each module's `run(args)` is
# set as the subparser's `func` default. Imported lazily so `hamjax --help` is fast.
_COMMANDS = {
    "demo": "hamjax.cli.demo",
    "simulate": "hamjax.cli.simulate",
    "experiment": "hamjax.cli.experiment",
    "identify": "hamjax.cli.identify",
    "reproduce": "hamjax.cli.reproduce",
    "study": "hamjax.cli.study",
    "diagnose": "hamjax.cli.diagnose",
    "blind": "hamjax.cli.blind",
}


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse's own usage errors: exit 2, no traceback
        self.print_usage(sys.stderr)
        print(f"hamjax: error: {message}", file=sys.stderr)
        raise SystemExit(2)


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The parser; with `argv`, a command module that defines `register_brief`
    (an entry without its costly details, e.g. every study's options) gets only
    that when another command is run."""
    chosen = next((a for a in (argv or []) if not a.startswith("-")), None)
    parser = _Parser(
        prog="hamjax",
        description="Identify Hammerstein systems with hard input nonlinearities "
        "and diagnose sim-to-real gaps.",
    )
    from .. import __version__

    parser.add_argument("--version", action="version", version=f"hamjax {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    for name, module in _COMMANDS.items():
        try:
            mod = importlib.import_module(module)
        except ModuleNotFoundError as err:
            if err.name == module:
                continue  # not built yet
            raise
        brief = chosen not in (None, name) and hasattr(mod, "register_brief")
        (mod.register_brief if brief else mod.register)(sub)
    from ._help import apply_conventions

    apply_conventions(parser)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console script and of `python -m hamjax`."""
    from .._errors import UserInputError
    from .._runtime import avoid_eigen_pool_hang, use_compilation_cache
    from .._x64 import enable_x64

    avoid_eigen_pool_hang()
    enable_x64()
    use_compilation_cache()
    argv = sys.argv[1:] if argv is None else argv
    parser = build_parser(argv)
    args = parser.parse_args(argv)
    verbose = bool(getattr(args, "verbose", False))
    start = time.perf_counter()
    try:
        with _quiet_stdout(bool(getattr(args, "quiet", False))):
            result = args.func(args)
    except (UserInputError, ValueError, OSError) as err:
        if not isinstance(err, UserInputError) and (verbose or _debug()):
            # A ValueError raised by our validation names the problem; --verbose
            # (or a debug environment variable) shows the traceback for bug reports.
            traceback.print_exc()
        print(f"hamjax: error: {_one_line(err)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("hamjax: interrupted; results already written are kept", file=sys.stderr)
        return 130
    if verbose:
        took = time.perf_counter() - start
        print(f"hamjax: {args.command} took {took:.1f} s", file=sys.stderr)
    return int(result or 0)


def _one_line(err: BaseException) -> str:
    """The message of `err` on one line; an OSError as `file: reason`."""
    if isinstance(err, OSError) and err.strerror:
        where = f"{err.filename}: " if err.filename else ""
        return f"{where}{err.strerror}"
    return " ".join(str(err).split("\n"))


def _quiet_stdout(quiet: bool):
    """Inside: stdout discarded when `quiet` (errors and warnings go to stderr)."""
    import contextlib
    import io

    return (
        contextlib.redirect_stdout(io.StringIO()) if quiet else contextlib.nullcontext()
    )


def _debug() -> bool:
    import os

    return bool(os.environ.get("HAMJAX_DEBUG"))


if __name__ == "__main__":
    sys.exit(main())
