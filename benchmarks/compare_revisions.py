"""Do two checkouts of hamjax compute the same thing? The layout issue's invariants.

For two source trees (e.g. a worktree of the commit before a restructuring and
this one) the script runs, each in its own fresh process with that tree first on
`PYTHONPATH`:

1. every registered study named in `STUDIES` at a fixed seed and small size, and
   compares every number of every JSON file it writes (timings excluded) to a
   relative tolerance `--rtol` (default 1e-9);
2. `hamjax diagnose` on blind sets made by the *new* tree (`hamjax blind make`,
   the cases are files, so both trees read the same bytes), and compares the
   effect named per case and `gap_after` (relative `--gap-rtol`, default 1e-6);
3. the wall time of each diagnosis call, of one case diagnosed cold (a fresh
   process, the compile cache off), of `hamjax study simulation-throughput` and
   of each hamjax method of `benchmarks/benchmark_throughput.py` (each tree's own
   copy, a small size), old and new alternating, `--repeats` times each, and
   reports the median ratio new/old (for the benchmark: of throughputs, so >1 is
   faster).

    python benchmarks/compare_revisions.py --old /path/to/old/tree --new . \\
        --out results/compare --cases 240

writes `compare.json` (per study: equal or the first differences; per blind set:
cases, same effect, max relative gap difference; timings and ratios) and prints a
summary. Exit 1 when anything differs.
"""

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path


# study -> extra arguments (tiny but non-trivial; each runs in a few seconds)
STUDIES = {
    "nbbi-rate": ["--ns", "3,6,12"],
    "fgi-rate": ["--ms", "1,2,4"],
    "fgi-pipeline": ["--noises", "0.1,0.3,1"],
    "nbbi-shapes": ["--levels", "3", "--hold", "4"],
    "recursive-pl-convergence": ["--orders", "1", "--periods", "40"],
    "recursive-pl-noise": ["--periods", "32"],
    "recursive-pl-excitation": ["--orders", "1,2"],
    "recursive-pl-tuning": ["--periods", "20"],
    "recursive-pl-vs-batch": ["--periods", "20"],
    "refinement-recursive-pl": ["--periods", "4", "--snrs", "20", "--no-timing"],
    "refinement-nbbi": ["--holds", "3", "--snrs", "40", "--dt", "0.1", "--no-timing"],
    "simulation-throughput": ["--samples", "200"],
}
# keys whose values are timings or machine facts, not results
VOLATILE = (
    "second",
    "time",
    "throughput",
    "per_s",
    "elapsed",
    "wall",
    "cost",
    "rate_",
    "created",
    "headline",
    "verdict",  # a date; text made of the numbers compared
)
BLIND_SETS = (("exact", 100), ("realistic", 0), ("realistic", 100))


def _hamjax(tree: Path, args: list[str], *, cwd: Path) -> float:
    env = dict(os.environ, PYTHONPATH=str(tree), HAMJAX_CACHE_DIR="off")
    start = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "hamjax", *args],
        cwd=cwd,
        env=env,
        check=True,
        stdout=subprocess.DEVNULL,
    )
    return time.perf_counter() - start


def _numbers(tree, path=""):
    """Flatten JSON into {path: value} for the comparable leaves."""
    if isinstance(tree, dict):
        out = {}
        for k, v in tree.items():
            if any(word in str(k).lower() for word in VOLATILE):
                continue
            out |= _numbers(v, f"{path}/{k}")
        return out
    if isinstance(tree, list):
        out = {}
        for i, v in enumerate(tree):
            out |= _numbers(v, f"{path}[{i}]")
        return out
    return {path: tree}


def _differences(old, new, rtol: float) -> list[str]:
    a, b = _numbers(old), _numbers(new)
    diffs = [f"{k}: only in one" for k in sorted(set(a) ^ set(b))]
    for k in sorted(set(a) & set(b)):
        x, y = a[k], b[k]
        if isinstance(x, float | int) and isinstance(y, float | int):
            if isinstance(x, bool) or isinstance(y, bool):
                same = x == y
            elif math.isnan(x) or math.isnan(y):
                same = math.isnan(x) and math.isnan(y)
            else:
                same = abs(x - y) <= rtol * max(abs(x), abs(y)) + 1e-300
        else:
            same = x == y
        if not same:
            diffs.append(f"{k}: {x!r} vs {y!r}")
    return diffs


def _json_files(folder: Path) -> dict[str, Path]:
    return {
        str(p.relative_to(folder)): p
        for p in folder.rglob("*.json")
        if "realisations" not in p.parts  # chunk manifests carry versions and times
    }


def compare_studies(old: Path, new: Path, out: Path, rtol: float) -> dict:
    report = {}
    for name, extra in STUDIES.items():
        folders = {}
        for label, tree in (("old", old), ("new", new)):
            folders[label] = out / "studies" / label / name
            argv = ["study", name, "--realisations", "4", "--chunk", "2", "--seed", "0"]
            argv += ["--quiet", "--out", str(folders[label]), *extra]
            _hamjax(tree, argv, cwd=out)
        a, b = _json_files(folders["old"]), _json_files(folders["new"])
        diffs = [f"{f}: only in one" for f in sorted(set(a) ^ set(b))]
        for f in sorted(set(a) & set(b)):
            old_json = json.loads(a[f].read_text())
            new_json = json.loads(b[f].read_text())
            diffs += [f"{f} {d}" for d in _differences(old_json, new_json, rtol)]
        report[name] = {"equal": not diffs, "differences": diffs[:20]}
        print(f"study {name}: {'equal' if not diffs else f'{len(diffs)} differences'}")
    return report


def compare_diagnoses(
    old: Path, new: Path, out: Path, cases: int, gap_rtol: float, repeats: int
) -> dict:
    report = {}
    for mode, seed in BLIND_SETS:
        label = f"{mode}_seed{seed}"
        blind = out / "blind" / label
        if not (blind / "truth.json").is_file():
            argv = ["blind", "make", "--cases", str(cases), "--seed", str(seed)]
            _hamjax(new, [*argv, "--realism", mode, "--out", str(blind)], cwd=out)
        case_dirs = sorted(str(p) for p in (blind / "cases").iterdir())
        walls = {"old": [], "new": []}
        for r in range(repeats):
            for tag, tree in (("old", old), ("new", new)):
                results = out / "diagnoses" / label / tag
                if results.exists() and r == 0:
                    subprocess.run(["rm", "-rf", str(results)], check=True)
                argv = ["diagnose", *case_dirs, "--out", str(results / f"run{r}")]
                walls[tag].append(_hamjax(tree, [*argv, "--quiet"], cwd=out))
        same, worst = 0, 0.0
        for case in case_dirs:
            name = Path(case).name
            d = [
                json.loads(
                    (
                        out / "diagnoses" / label / t / "run0" / name / "diagnosis.json"
                    ).read_text()
                )
                for t in ("old", "new")
            ]
            same += d[0]["effect"] == d[1]["effect"]
            g0, g1 = d[0]["gap_after"], d[1]["gap_after"]
            worst = max(worst, abs(g0 - g1) / max(abs(g0), abs(g1), 1e-300))
        med = {t: statistics.median(w) for t, w in walls.items()}
        report[label] = {
            "cases": len(case_dirs),
            "same_effect": same,
            "max_relative_gap_after_difference": worst,
            "gap_within_tolerance": worst <= gap_rtol,
            "wall_s": walls,
            "s_per_case_median": {t: m / len(case_dirs) for t, m in med.items()},
            "ratio_new_over_old": med["new"] / med["old"],
        }
        print(
            f"diagnose {label}: same effect {same}/{len(case_dirs)}, max rel. "
            f"gap_after difference {worst:.2e}, wall new/old {med['new'] / med['old']:.3f}"
        )
    return report


def compare_throughput(old: Path, new: Path, out: Path, repeats: int) -> dict:
    walls = {"old": [], "new": []}
    for r in range(repeats):
        for tag, tree in (("old", old), ("new", new)):
            folder = out / "throughput" / tag / f"run{r}"
            argv = ["study", "simulation-throughput", "--realisations", "4096"]
            argv += ["--samples", "1000", "--chunk", "512", "--quiet", "--out"]
            walls[tag].append(_hamjax(tree, [*argv, str(folder)], cwd=out))
    med = {t: statistics.median(w) for t, w in walls.items()}
    print(f"simulation-throughput wall new/old {med['new'] / med['old']:.3f}")
    return {"wall_s": walls, "ratio_new_over_old": med["new"] / med["old"]}


def compare_cold(old: Path, new: Path, out: Path, repeats: int) -> dict:
    """One case, a fresh process, no compile cache: what a first call costs."""
    blind = out / "blind" / "realistic_seed0"
    if not (blind / "truth.json").is_file():
        argv = ["blind", "make", "--cases", "1", "--seed", "0", "--realism"]
        _hamjax(new, [*argv, "realistic", "--out", str(blind)], cwd=out)
    case = str(sorted((blind / "cases").iterdir())[0])
    walls = {"old": [], "new": []}
    for r in range(repeats):
        for tag, tree in (("old", old), ("new", new)):
            folder = out / "cold" / tag / f"run{r}"
            argv = ["diagnose", case, "--out", str(folder), "--quiet", "--force"]
            walls[tag].append(_hamjax(tree, argv, cwd=out))
    med = {t: statistics.median(w) for t, w in walls.items()}
    print(f"diagnose one case cold wall new/old {med['new'] / med['old']:.3f}")
    return {
        "case": case,
        "wall_s": walls,
        "ratio_new_over_old": med["new"] / med["old"],
    }


def compare_benchmark(old: Path, new: Path, out: Path, repeats: int) -> dict:
    """Each tree's own throughput benchmark at a small size; throughput ratios."""
    tables = {"old": [], "new": []}
    for r in range(repeats):
        for tag, tree in (("old", old), ("new", new)):
            folder = out / "benchmark" / tag / f"run{r}"
            env = dict(os.environ, PYTHONPATH=str(tree), HAMJAX_CACHE_DIR="off")
            argv = [
                sys.executable,
                str(tree / "benchmarks" / "benchmark_throughput.py"),
            ]
            argv += ["--realisations", "1024", "--samples", "4000", "--no-ablation"]
            argv += ["--memory-realisations", "0", "--out", str(folder)]
            subprocess.run(argv, cwd=out, env=env, check=True, capture_output=True)
            table = json.loads((folder / "benchmark.json").read_text())["table"]
            tables[tag].append(table)
    ratios = {}
    for workload, methods in tables["new"][0].items():
        for method in methods:
            if not method.startswith("hamjax"):
                continue  # the peers are the same code in both trees
            rates = {
                t: statistics.median(tab[workload][method] for tab in tables[t])
                for t in tables
            }
            if rates["old"] and rates["new"]:
                ratios[f"{workload}/{method}"] = rates["new"] / rates["old"]
    for key, ratio in ratios.items():
        print(f"benchmark {key} throughput new/old {ratio:.3f}")
    return {"tables": tables, "throughput_ratio_new_over_old": ratios}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--old", type=Path, required=True, help="old source tree")
    parser.add_argument("--new", type=Path, default=Path("."), help="new source tree")
    parser.add_argument("--out", type=Path, required=True, help="output folder")
    parser.add_argument("--cases", type=int, default=240, help="cases per blind set")
    parser.add_argument("--repeats", type=int, default=1, help="timed runs of each")
    parser.add_argument("--rtol", type=float, default=1e-9)
    parser.add_argument("--gap-rtol", type=float, default=1e-6)
    parser.add_argument(
        "--skip",
        default="",
        help="comma-separated parts to skip: studies,diagnose,cold,throughput,benchmark",
    )
    args = parser.parse_args(argv)
    for tree in (args.old, args.new):
        if not (tree / "hamjax" / "__init__.py").is_file():
            parser.error(f"{tree}: not a hamjax source tree (no hamjax/__init__.py)")
    old, new = args.old.resolve(), args.new.resolve()
    args.out.mkdir(parents=True, exist_ok=True)
    out = args.out.resolve()
    skip = set(filter(None, args.skip.split(",")))
    report = {"old": str(old), "new": str(new), "command": sys.argv}
    if "studies" not in skip:
        report["studies"] = compare_studies(old, new, out, args.rtol)
    if "diagnose" not in skip:
        report["diagnose"] = compare_diagnoses(
            old, new, out, args.cases, args.gap_rtol, args.repeats
        )
    if "cold" not in skip:
        report["cold"] = compare_cold(old, new, out, args.repeats)
    if "throughput" not in skip:
        report["throughput"] = compare_throughput(old, new, out, args.repeats)
    if "benchmark" not in skip:
        report["benchmark"] = compare_benchmark(old, new, out, args.repeats)
    (out / "compare.json").write_text(json.dumps(report, indent=2))
    ok = all(s["equal"] for s in report.get("studies", {}).values()) and all(
        d["same_effect"] == d["cases"] and d["gap_within_tolerance"]
        for d in report.get("diagnose", {}).values()
    )
    print(f"wrote {out / 'compare.json'}; {'all equal' if ok else 'DIFFERENCES'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
