"""Demo section: the gap diagnosis on a real plant, the cascaded tanks of
`../shared/data/real/` (estimation and test records as the benchmark splits them;
no model given, so hamjax fits its own nominal first). Skipped, with a note, where
`../shared` is not beside the clone."""

from pathlib import Path


# The repository's parent holds `shared/` (as CI and the studies lay it out).
REAL = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "real"


def run(key, out: Path) -> list[tuple[str, str]]:
    del key  # measured data: nothing random
    from ..diagnosis.diagnose import diagnose_gap
    from ..diagnosis.nominal_fit import describe_structure, fit_nominal
    from ..diagnosis.report import write_diagnosis
    from ..io import model_to_dict, write_json
    from ..papers.gap.real_data import gap_records, real_cases
    from ..plotting.diagnosis import save_diagnosis_figures

    cases = real_cases(REAL) if REAL.is_dir() else {}
    if "cascaded_tanks" not in cases:
        print(f"[demo] real data: skipped ({REAL} not found)")
        return []
    est, val, documented = cases["cascaded_tanks"]
    est, val = gap_records(est, val)  # as `hamjax study real-data-gap` writes it
    dt = float(est["t"][1] - est["t"][0])
    plant = fit_nominal(dt, est)
    d = diagnose_gap(plant, dt, est, val, fitted=True)
    folder = Path(out) / "real_data"
    name = "cascaded tanks (real measurements)"
    write_diagnosis(
        d,
        folder,
        name,
        nominal="fitted by hamjax on the estimation record: "
        + describe_structure(plant),
    )
    write_json(folder / "nominal_model.json", model_to_dict(plant, dt))
    save_diagnosis_figures(d, folder, name)
    p = d.probabilities[d.effect]
    return [
        (
            str(folder / "report.md"),
            f"diagnosis of the cascaded tanks: named {d.effect} (probability "
            f"{p:.2f}); documented: {documented}",
        ),
        (str(folder / "validation.png"), "fitted nominal vs augmented vs measured"),
        (str(folder / "nominal_model.json"), "the nominal hamjax fitted"),
    ]
