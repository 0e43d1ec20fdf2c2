"""Benchmark: XLA compile options for the diagnosis's fit program (issue 7).

Question: `hamjax diagnose` compiles one batched Levenberg-Marquardt program per call
(`hamjax.diagnosis.fit`); for a single case that compilation is most of the wall
time. How much compile time do XLA's CPU options save
(`fit.PROGRAMS.compiler_options`, against XLA's defaults), and what does each cost in run
time, for one case and for many cases in one call? Do the diagnoses stay the same?

Every configuration runs as its own fresh `hamjax diagnose` process (the on-disk
compilation cache off), alternating configurations `--repeats` times so that a
slow spell of the machine hits all of them alike. Reported per configuration:
median wall time of the process, of tracing + lowering, of XLA's compilation, and
the rest (reading, fits, writing); ratios against XLA's defaults in the same run;
and whether every case was given the same effect as with the defaults.

    hamjax blind make --cases 240 --seed 100 --realism realistic --out B
    python benchmarks/diagnosis_compile_options.py --single B/cases/case_0007 \\
        --many B/cases --limit 60 --out results/compile-options

Writes `compile_options.json` into `--out`.
"""

import argparse
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


HERE = Path(__file__).resolve()
CONFIGS = {
    "xla-defaults": {},
    "hamjax": None,  # fit.PROGRAMS.compiler_options as shipped
    "hamjax+opt0": {"xla_backend_optimization_level": 0},  # added to the shipped
}


def _covered(spans: list[tuple[float, float]]) -> float:
    """The time inside at least one of the spans (the wall-clock time spent
    compiling: `CompiledPrograms.get_each` compiles the devices' programs at
    the same time, so the spans overlap)."""
    total, end = 0.0, -math.inf
    for a, b in sorted(spans):
        total += max(0.0, b - max(a, end))
        end = max(end, b)
    return total


def child(config: str, cases: list[str], out: str) -> None:
    """Run `hamjax diagnose` in this process with `config`; print timings as JSON."""
    t_start = time.perf_counter()
    import hamjax.diagnosis.fit as fit
    from hamjax.cli.main import main

    extra = CONFIGS[config]
    if extra == {}:
        fit.PROGRAMS.compiler_options = {}
    elif extra is not None:
        fit.PROGRAMS.compiler_options = {**fit.PROGRAMS.compiler_options, **extra}
    times = {"lower": 0.0, "compile": 0.0}
    lower, compile_ = fit.PROGRAMS.programs["one"].lower, fit.PROGRAMS._compile

    class Timed:
        def lower(self, *args, **kwargs):
            t = time.perf_counter()
            out = lower(*args, **kwargs)
            times["lower"] += time.perf_counter() - t
            return out

    spans = []  # (start, end) of each compilation; the devices' run at once

    def timed_compile(lowered):
        t = time.perf_counter()
        out = compile_(lowered)
        spans.append((t, time.perf_counter()))
        return out

    fit.PROGRAMS.programs["one"] = Timed()
    fit.PROGRAMS._compile = timed_compile
    t_import = time.perf_counter() - t_start
    status = main(["diagnose", *cases, "--out", out])
    times.update(compile=_covered(spans), import_=t_import, status=status)
    print(json.dumps(times))


def run_config(config: str, cases: list[str]) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        env = {**os.environ, "HAMJAX_CACHE_DIR": "off"}
        cmd = [sys.executable, str(HERE), "--child", config, "--out", tmp, *cases]
        t = time.perf_counter()
        proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
        wall = time.perf_counter() - t
        if proc.returncode != 0:
            sys.exit(f"{config} failed:\n{proc.stderr[-2000:]}")
        times = json.loads(proc.stdout.strip().splitlines()[-1])
        effects = {}
        for case in cases:
            name = Path(case).name
            folder = Path(tmp) if len(cases) == 1 else Path(tmp) / name
            with open(folder / "diagnosis.json") as f:
                effects[name] = json.load(f)["effect"]
    times["wall"] = wall
    times["rest"] = wall - times["lower"] - times["compile"]
    return {"times": times, "effects": effects}


def summarise(runs: dict[str, list[dict]]) -> dict:
    keys = ("wall", "lower", "compile", "rest")
    med = {
        c: {k: statistics.median(r["times"][k] for r in rs) for k in keys}
        for c, rs in runs.items()
    }
    ref_effects = runs["xla-defaults"][0]["effects"]
    out = {}
    for c, m in med.items():
        same = sum(
            r["effects"][k] == v for r in runs[c] for k, v in ref_effects.items()
        ) / (len(runs[c]) * len(ref_effects))
        out[c] = {
            "median_s": m,
            "all_s": {k: [r["times"][k] for r in runs[c]] for k in keys},
            "ratio_to_defaults": {
                k: m[k] / med["xla-defaults"][k] for k in ("wall", "compile", "rest")
            },
            "same_effect_as_defaults": same,
        }
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--single", help="one case folder (the one-case call)")
    ap.add_argument("--many", help="a folder of case folders (the many-case call)")
    ap.add_argument("--limit", type=int, default=60, help="cases of --many used")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", required=True)
    ap.add_argument("--child", help=argparse.SUPPRESS)
    ap.add_argument("cases", nargs="*", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        child(args.child, args.cases, args.out)
        return 0
    workloads = {}
    if args.single:
        workloads["one_case"] = [args.single]
    if args.many:
        workloads["many_cases"] = sorted(str(p) for p in Path(args.many).iterdir())[
            : args.limit
        ]
    if not workloads:
        ap.error("give --single CASE and/or --many DIR")
    result = {
        "command": " ".join([Path(sys.argv[0]).name, *sys.argv[1:]]),
        "machine": {"cpus": os.cpu_count(), "platform": platform.platform()},
        "configs": {
            c: (v if v is not None else "fit.PROGRAMS.compiler_options")
            for c, v in CONFIGS.items()
        },
    }
    for name, cases in workloads.items():
        configs = list(CONFIGS) if name == "one_case" else ["xla-defaults", "hamjax"]
        runs: dict[str, list] = {c: [] for c in configs}
        for rep in range(args.repeats):
            for c in configs:
                runs[c].append(run_config(c, cases))
                t = runs[c][-1]["times"]
                print(
                    f"{name} {c} #{rep}: wall {t['wall']:.2f} s, compile "
                    f"{t['compile']:.2f} s, trace+lower {t['lower']:.2f} s",
                    flush=True,
                )
        result[name] = {"cases": len(cases), **summarise(runs)}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "compile_options.json").write_text(json.dumps(result, indent=2))
    print(f"wrote {out / 'compile_options.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
