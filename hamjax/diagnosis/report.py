"""Write `diagnosis.json` (the contract fields and more) and a short `report.md`."""

import math
from pathlib import Path

from ..io import atomic_write_text, write_json


def diagnosis_dict(d) -> dict:
    """The JSON form of a `GapDiagnosis` (contract fields first)."""
    return {
        "effect": d.effect,
        "gap_before": d.gap_before,
        "gap_after": d.gap_after,
        "noise_floor": d.noise_floor,
        "ranking": d.ranking,
        "where": d.where,
        "probabilities": d.probabilities,
        "shrink": d.shrink,
        "gap_definition": d.gap_definition,
        "tests": d.tests,
    }


def _clean(x):
    if isinstance(x, dict):
        return {k: _clean(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_clean(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return None if math.isnan(x) else (1e308 if x > 0 else -1e308)
    if hasattr(x, "item"):
        return _clean(x.item())
    return x


def _merged_bands(bands: list[dict]) -> list[tuple[float, float]]:
    """Significant frequency bands with adjacent ones joined."""
    out: list[list[float]] = []
    for x in bands:
        lo, hi = float(x["f_low_hz"]), float(x["f_high_hz"])
        if out and math.isclose(out[-1][1], lo, rel_tol=1e-9):
            out[-1][1] = hi
        else:
            out.append([lo, hi])
    return [(lo, hi) for lo, hi in out]


def _number(x) -> str:
    """A value for a person: floats to 3 significant digits, a dict's values so
    (`{none 0.362, drift 0.0236}`)."""
    if isinstance(x, dict):
        return "{" + ", ".join(f"{a} {_number(b)}" for a, b in x.items()) + "}"
    if isinstance(x, bool) or not isinstance(x, float):
        return str(x)
    return f"{x:.3g}"


def _significant_axes(where: dict) -> list[str]:
    b = where["before"]
    out = []
    bands = _merged_bands([x for x in b["frequency"] if x["significant"]])
    if bands:
        out.append(
            "frequency: above the floor in "
            + ", ".join(f"{lo:.3g}-{hi:.3g} Hz" for lo, hi in bands)
        )
    # With an identity map (or any map leaving the bins alike) u repeats v.
    same_bins = [(x["v_low"], x["v_high"]) for x in b["amplitude_v"]] == [
        (x["u_low"], x["u_high"]) for x in b["amplitude_u"]
    ]
    for key, label in (("amplitude_v", "v"), ("amplitude_u", "u")):
        if label == "u" and same_bins:
            continue
        bins = [x for x in b[key] if x["significant"]]
        if bins:
            out.append(
                f"amplitude ({label}): "
                + ", ".join(
                    f"[{x[f'{label}_low']:.3g}, {x[f'{label}_high']:.3g}] "
                    f"RMS {x['rms_over_floor']:.2g}x floor"
                    for x in bins
                )
            )
    dirn = b["direction"]
    if dirn.get("significant"):
        out.append(
            f"direction: rising mean {dirn['rising']['mean']:.3g} vs falling "
            f"{dirn['falling']['mean']:.3g} (z = {dirn['z']:.1f}): memory"
        )
    tm = b["time"]
    out.append(
        f"time: transient RMS {tm['transient']['rms']:.3g} vs steady "
        f"{tm['steady']['rms']:.3g}; residual-input correlation peaks at lag "
        f"{tm['cross_correlation']['max_abs_lag']}"
        + (" (significant)" if tm["cross_correlation"]["significant"] else "")
    )
    if tm["trend"]["significant"]:
        out.append(f"time: slow trend {tm['trend']['slope_per_s']:.3g} per s")
    bv = [k for k, x in b["billings_voon"].items() if x["exceeded"]]
    if bv:
        out.append("Billings-Voon tests exceeded: " + ", ".join(bv))
    if "periodic" in b:
        p = b["periodic"]
        out.append(
            f"periodic input: deterministic error RMS {p['deterministic_rms']:.3g}, "
            f"noise RMS {p['noise_rms']:.3g} (average over periods)"
        )
    return out


def where_in_brief(where: dict) -> str:
    """Where the gap of the nominal model lies, in one line: the frequency band
    holding most of its power above the floor, and memory (rising vs falling)
    when that is significant."""
    b = where["before"]
    sig = [x for x in b["frequency"] if x["significant"]]
    parts = []
    if sig:
        top = max(sig, key=lambda x: x["power_over_floor"])
        parts.append(
            f"{top['f_low_hz']:.3g}-{top['f_high_hz']:.3g} Hz "
            f"({top['power_over_floor']:.3g}x floor)"
        )
    else:
        parts.append("no band above the floor")
    if b["direction"].get("significant"):
        parts.append("depends on the direction of motion")
    if b["time"]["trend"]["significant"]:
        parts.append("slow trend")
    return "; ".join(parts)


def report_markdown(d, name: str = "case", nominal: str | None = None) -> str:
    """A page a person reads in two minutes. `nominal`: where the nominal model
    came from (e.g. the user's `model.json`, or fitted by hamjax)."""
    lines = [
        f"# Sim-to-real gap: {name}",
        "",
        f"**Effect named: `{d.effect}`**",
        "",
    ]
    top = sorted(d.probabilities.items(), key=lambda kv: -kv[1])
    shown = [f"{k} {v:.2f}" for k, v in top if v >= 0.01][:4]
    lines.append(f"- probabilities: {', '.join(shown)}")
    close = [k for k, v in top[1:] if v >= 0.5 * top[0][1] and k != "unexplained"]
    if close:
        lines.append(
            f"- `{d.effect}` and {', '.join(f'`{k}`' for k in close)} cannot be told "
            "apart on these records: their validation errors are within the "
            "evidence of a few samples (see the candidates below)"
        )
    two = {r: k for r, k in d.where.get("input_levels", {}).items() if k <= 2}
    if two:
        which, there = (
            ("the inputs of both records take", "those records")
            if len(two) == 2
            else (f"the {next(iter(two))} record's input takes", "that record")
        )
        points = "one point" if max(two.values()) < 2 else "two points"
        lines.append(
            f"- {which} at most two levels: a static map of the input is seen "
            f"there at {points}, where any map is a gain and an offset, so on "
            f"{there} a static effect on the input (`saturation`, `dead_zone`, "
            "`preload`) cannot be told apart from a gain mismatch "
            "(`parameter_mismatch`)"
        )
    if nominal is not None:
        lines.append(f"- nominal model: {nominal}")
    ref = d.tests.get("reference", {})
    if ref.get("fitted_nominal"):
        lines.append(
            "- reference: "
            + (
                "the re-fit of hamjax's own nominal, which improves on it "
                "significantly (the effects are judged against the re-fit; gap "
                "before stays the nominal's)"
                if ref.get("model") == "refit"
                else "hamjax's own nominal"
            )
            + "; the nominal was fitted here, so a re-fit of it is no verdict "
            "(`parameter_mismatch` is not named)"
        )
    fb = d.where.get("feedback", {})
    if fb.get("closed_loop"):
        lines.append(
            f"- the record looks closed-loop: the output predicts the input beyond "
            f"the input's own past (Granger test for feedback at 1 %: F = "
            f"{fb['z']:.1f} > {fb['threshold']:.1f}, strongest at output lag "
            f"{fb['lag']}): v is a controller's output, so the noise reaches it and "
            "simulation-error fits can be biased"
        )
    dep = d.tests.get("input_dependence", {})
    if dep.get("dependent") and d.effect not in ("drift", "coloured_noise", "none"):
        lines.append(
            "- a noise model alone does not explain the gap: the reference's "
            "one-step-ahead errors through it depend on the input (residual-input "
            f"independence test at 1 %: F = {dep['F']:.2f} > {dep['threshold']:.2f}, "
            f"p = {dep['p_value']:.2g}; what the input explains has "
            f"{dep.get('explained', float('nan')):.2g} times the variance of the "
            f"rest), so `{d.effect}` is named with it; what the effect's "
            "simulation leaves of the gap is that noise (a trend or coloured "
            "noise on top)"
        )
    lines += [
        f"- gap before (nominal model): {d.gap_before:.4g} (units of y)",
        f"- gap after (nominal + named effect, fitted on estimation data): "
        f"{d.gap_after:.4g} (units of y)",
        f"- noise floor: {d.noise_floor:.4g} (units of y); shrink "
        f"(gap_before - gap_after)/(gap_before - noise) = {d.shrink:.2f}",
        f"- gap measured as: {d.gap_definition}",
        "",
        "## Where the gap lies (validation residual of the nominal model)",
        "",
    ]
    lines += [f"- {s}" for s in _significant_axes(d.where)]
    lines += [
        "",
        "## Candidates (best first)",
        "",
        "| effect | gap after (units of y) | measure |",
        "|---|---|---|",
    ]
    for c in d.ranking:
        lines.append(f"| {c['effect']} | {c['gap_after']:.4g} | {c['measure']} |")
    chosen = d.ranking[0] if d.effect not in ("none",) else None
    if chosen is not None:
        lines += ["", f"## Fitted parameters of `{chosen['effect']}` (value ± std)", ""]
        for k, x in chosen["params"].items():
            if k == "nominal_refit":
                continue
            if isinstance(x["value"], str):  # e.g. friction's `velocity`
                lines.append(f"- {k}: {x['value']}")
                continue
            lines.append(f"- {k}: {x['value']:.4g} ± {x['std']:.2g}")
        refit = chosen["params"].get("nominal_refit", {})
        if refit:
            lines.append(
                "- re-fitted nominal: "
                + ", ".join(f"{k} {x['value']:.4g}" for k, x in refit.items())
            )
    lines += ["", "## Significance", ""]
    for k, x in d.tests.items():
        lines.append(f"- {k}: " + ", ".join(f"{a}={_number(b)}" for a, b in x.items()))
    lines += [
        "",
        "Rule: held-out validation improvement with batch-means z > 3.5 and above "
        "2 % of the noise variance (z > 3 for a structural effect against the "
        "re-fit), or a structural effect whose likelihood ratio against the re-fit "
        "on the estimation record exceeds the Bonferroni chi-square threshold and "
        "that validation confirms (z > 2); a noise model is named only where "
        "its one-step-ahead errors do not depend on the input (open-loop "
        "records, test at 1 %); see `hamjax.diagnosis.attribute`.",
        "",
    ]
    return "\n".join(lines)


def write_diagnosis(
    d, out: Path, name: str = "case", nominal: str | None = None
) -> None:
    """Write `diagnosis.json` and `report.md` into `out` (the figures are
    `hamjax.plotting.diagnosis.save_diagnosis_figures`); `nominal` as in
    `report_markdown`."""
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "diagnosis.json", _clean(diagnosis_dict(d)))
    atomic_write_text(out / "report.md", report_markdown(d, name, nominal))
