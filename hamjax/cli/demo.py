"""`hamjax demo [--out DIR]`: the pictures a person wants first, on built-in plants."""

import argparse
import time
import traceback
from pathlib import Path

import jax.random as jr

from .._runtime import same_rounding_in_every_lane
from ._common import optional_module


# Each section module defines `run(key, out) -> [(file, description), ...]`. A
# section that fails is reported and the others still run (nothing is lost).
SECTIONS = [
    ("core: plants, inputs, outputs", "hamjax.demo.core"),
    (
        "seed 001: recursive identification (Fig. 3)",
        "hamjax.demo.recursive_pl",
    ),
    (
        "seed 000: NBBI + FGI (Figs. 5, 6, Bode)",
        "hamjax.demo.backlash_frequency",
    ),
    ("refinement: closed form vs refined vs CRLB", "hamjax.demo.refinement"),
    ("diagnosis of a withheld-effect case", "hamjax.demo.diagnosis"),
    ("diagnosis of a real plant (cascaded tanks)", "hamjax.demo.real_data"),
]


def register(sub) -> None:
    p = sub.add_parser("demo", help="run the built-in demonstration (writes figures)")
    p.add_argument(
        "--out",
        type=Path,
        default=Path("hamjax-demo"),
        help="output folder (default hamjax-demo/)",
    )
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import matplotlib

    matplotlib.use("Agg")
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    same_rounding_in_every_lane()  # it diagnoses; before the first computation
    key = jr.key(args.seed)
    lines, failed = [], 0
    start = time.perf_counter()
    for i, (title, module) in enumerate(SECTIONS):
        mod = optional_module(module)
        if mod is None:
            continue
        t0 = time.perf_counter()
        print(f"[demo] {title} ...", flush=True)
        try:
            made = mod.run(jr.fold_in(key, i), out)
        except Exception:  # a broken section must not lose the others' results
            failed += 1
            traceback.print_exc()
            lines.append(f"## {title}\n\nFAILED (see the console output).\n")
            continue
        lines.append(f"## {title} ({time.perf_counter() - t0:.1f} s)\n")
        lines.extend(
            f"- [`{_relative(name, out)}`]({_relative(name, out)}): {desc}"
            for name, desc in made
        )
        lines.append("")
        _write_summary(out, lines, time.perf_counter() - start)
    _write_summary(out, lines, time.perf_counter() - start)
    print(f"[demo] wrote {out}/summary.md ({time.perf_counter() - start:.0f} s)")
    return 1 if failed else 0


def _write_summary(out: Path, lines: list[str], elapsed: float) -> None:
    from ..io import atomic_write_text

    head = ["# hamjax demo", "", f"Made by `hamjax demo` in {elapsed:.0f} s.", ""]
    atomic_write_text(out / "summary.md", "\n".join(head + lines) + "\n")


def _relative(name, out: Path) -> str:
    """`name` (a file a section wrote: a bare name, or a path through `out`)
    relative to `out`, where summary.md is: the link works from the summary."""
    path, root = Path(name), Path(out).resolve()
    if not path.is_absolute() and not (Path(out) / path).exists():
        path = path.resolve()  # a path given through `out`, e.g. OUT/diagnosis/x
    if path.is_absolute():
        resolved = path.resolve()
        return (
            str(resolved.relative_to(root))
            if resolved.is_relative_to(root)
            else str(path)
        )
    return str(path)
