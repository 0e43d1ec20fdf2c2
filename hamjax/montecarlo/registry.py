"""Study registry: the modules of the given study packages are discovered by name.

The engine knows no paper: the caller names the packages to search (the command
line passes `hamjax.papers.STUDY_PACKAGES`).

A study module defines

- `NAME: str` (the command-line name, e.g. `"simulation-throughput"`),
- `DESCRIPTION: str` (one line, shown by `hamjax study --list`),
- optional `OPTIONS`, a tuple of `StudyOption`s: the study's own command-line
  options, read in `run` with `option_values(args, OPTIONS)`; optional
  `DEFAULT_REALISATIONS` and `DEFAULT_CHUNK`, optional `SPLIT_CPU = True` when
  its work shards over devices and `hamjax study` should expose each CPU core as
  a JAX device before starting, optional `DIAGNOSES = True` when it diagnoses
  cases, whose names must not depend on the cases batched with them
  (`hamjax study` then caps XLA's ISA, `_runtime.same_rounding_in_every_lane`),
- `run(key, *, realisations, chunk, out, quiet, args) -> dict`, which writes its
  figures and a JSON summary into the folder `out` and returns the summary.

Adding a study is adding a module: no shared file changes. `register_study` adds
one from elsewhere (for example a test) for the lifetime of the process.
"""

import importlib
import pkgutil
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

from .._errors import UserInputError


@dataclass(frozen=True)
class Study:
    """A registered study (see the module docstring for the meaning of the fields)."""

    name: str
    description: str
    run: Callable[..., dict]
    add_arguments: Callable[[Any], None] | None = None
    default_realisations: int = 1000
    default_chunk: int = 256
    split_cpu: bool = False
    diagnoses: bool = False


_REGISTERED: dict[str, Study] = {}


@dataclass(frozen=True)
class StudyOption:
    """A study's own command-line option `--<name with - for _>`.

    `type` parses the text (an `argparse` type); `default` is the parsed value used
    when the option is absent, also when `run` is called without parsed arguments.
    `negate=True` makes a boolean `--no-<name>` flag whose default is `True`.
    """

    name: str
    default: Any
    help: str
    type: Callable[[str], Any] = str
    negate: bool = False

    def add_to(self, parser) -> None:
        """Add this option to an `argparse` parser."""
        flag = self.name.replace("_", "-")
        if self.negate:
            parser.add_argument(
                f"--no-{flag}", dest=self.name, action="store_false", help=self.help
            )
        else:
            parser.add_argument(
                f"--{flag}", type=self.type, default=self.default, help=self.help
            )


def option_values(args, options: Sequence[StudyOption]) -> SimpleNamespace:
    """The value of each of `options` in `args` (a parsed namespace, or `None`),
    with its default where `args` lacks it."""
    return SimpleNamespace(
        **{o.name: getattr(args, o.name, o.default) for o in options}
    )


def register_study(
    name: str,
    *,
    description: str,
    run: Callable[..., dict],
    add_arguments: Callable[[Any], None] | None = None,
    default_realisations: int = 1000,
    default_chunk: int = 256,
) -> Study:
    """Register a study defined outside the study packages (e.g. in a test)."""
    if not isinstance(name, str) or not name or " " in name:
        raise ValueError(f"study name must be a non-empty word; got {name!r}")
    study = Study(
        name, description, run, add_arguments, default_realisations, default_chunk
    )
    _REGISTERED[name] = study
    return study


def discover_studies(packages: Sequence[str] = ()) -> dict[str, Study]:
    """All studies, sorted by name: the modules of `packages` (dotted names of
    packages; modules starting with `_` are skipped), then the registered ones.

    A module that fails to import is listed with the error as its description and
    a `run` that raises it, so one broken study does not break the others.
    """
    found: dict[str, Study] = {}
    for package_name in packages:
        package = importlib.import_module(package_name)
        for info in pkgutil.iter_modules(package.__path__):
            if info.name.startswith("_"):
                continue
            module_name = f"{package.__name__}.{info.name}"
            try:
                module = importlib.import_module(module_name)
                study = _from_module(module)
            except Exception as err:  # noqa: BLE001 - reported, not swallowed
                study = _broken(info.name.replace("_", "-"), module_name, err)
            if study.name in found:
                raise ValueError(
                    f"study name {study.name!r} defined twice ({module_name})"
                )
            found[study.name] = study
    found.update(_REGISTERED)
    return dict(sorted(found.items()))


def get_study(name: str, packages: Sequence[str] = ()) -> Study:
    """The study called `name`; `UserInputError` listing the known names otherwise."""
    studies = discover_studies(packages)
    if name not in studies:
        known = ", ".join(studies) or "(none)"
        raise UserInputError(f"unknown study {name!r}; known studies: {known}")
    return studies[name]


def _from_module(module) -> Study:
    for attr, kind in (("NAME", str), ("DESCRIPTION", str)):
        if not isinstance(getattr(module, attr, None), kind):
            raise TypeError(f"study module {module.__name__} must define {attr}: str")
    if not callable(getattr(module, "run", None)):
        raise TypeError(f"study module {module.__name__} must define run(key, ...)")
    return Study(
        name=module.NAME,
        description=module.DESCRIPTION,
        run=module.run,
        add_arguments=_options_adder(getattr(module, "OPTIONS", ())),
        default_realisations=getattr(module, "DEFAULT_REALISATIONS", 1000),
        default_chunk=getattr(module, "DEFAULT_CHUNK", 256),
        split_cpu=bool(getattr(module, "SPLIT_CPU", False)),
        diagnoses=bool(getattr(module, "DIAGNOSES", False)),
    )


def _options_adder(options: Sequence[StudyOption]):
    if not options:
        return None

    def add_arguments(parser) -> None:
        for option in options:
            option.add_to(parser)

    return add_arguments


def _broken(name: str, module_name: str, err: Exception) -> Study:
    message = f"cannot be imported: {type(err).__name__}: {err}"

    def run(*args, **kwargs):
        raise UserInputError(f"study {name} ({module_name}) {message}")

    return Study(name=name, description=f"({message})", run=run)
