"""Adapters: the measured datasets of `../shared/data/real/` as gap-case folders.

Each adapter reads the dataset in place (never copied into the repository), picks
the input/output columns and applies the split below (what each dataset's
SOURCE.md or the issue names as its split). This module knows the datasets by
name; the diagnosis does not: `write_real_cases` writes plain case folders
(`estimation.csv`/`validation.csv`, no `model.json`, so the default nominal of
`diagnosis.nominal_fit` is fitted on the estimation record), and the one
pre-processing step, centring, is decided from the records alone (`from_rest`).
Splits:

| case | input -> output | estimation / validation | literature |
|---|---|---|---|
| cascaded_tanks | u -> y, Ts 4 s | estimation.csv / test.csv (standard) | overflow saturation, sqrt outflow |
| ced_prbs | u2 -> z2 / u1 -> z1, Ts 20 ms | the +-1.5 PRBS record / the +-1.0 record | output absolute value |
| emps | vir -> qm, decimated x10 | DATA_EMPS / DATA_EMPS_PULSES (standard), first 8000 ms each | Coulomb friction, offset, integrator |
| silverbox | u -> y | multisine part 40650:127400: first 75 % / the rest (standard) | feedback cubic stiffness |
| ball_beam | u -> y, Ts 0.1 s | first / second half | none listed |
| heat_exchanger | q -> th, Ts 1 s | first / second half | nonlinear, non-minimum phase |
| robot_arm | u -> y, Ts not given (1) | first / second half | none listed |
| f16_level3_to_2 | Force -> Acceleration2, 400 Hz block-averaged x8 | level 3 / level 2 (standard), second period each | clearance + friction in feedback, ~10 modes |
| hsm150_pos, hsm150_neg | torque_in -> vel, 1 ms decimated x10 | step to 0.06 / 0.065 N m; to -0.04 / -0.045 N m | none documented |
| hsm150_pos_to_neg | torque_in -> vel | step to 0.06 / step to -0.04 N m (opposite operating points) | asymmetric friction plausible |
| stiction_loop_XXX | op -> pv, Ts 10 s | first / second half | labels withheld |
"""

from pathlib import Path

import numpy as np

from ...io import write_csv


def _csv(path: Path) -> dict:
    with open(path) as f:
        header = f.readline().strip().split(",")
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return {h: data[:, i] for i, h in enumerate(header)}


def _f16_columns(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Force and Acceleration2 (next to the nonlinear interface) of an F-16 CSV
    (quoted header, `Fs` only in row 1, trailing empty column)."""
    data = np.loadtxt(path, delimiter=",", skiprows=1, usecols=(0, 3), ndmin=2)
    return data[:, 0], data[:, 1]


def _rec(v, y, dt) -> dict:
    v, y = np.asarray(v, float), np.asarray(y, float)
    return {"t": np.arange(v.shape[0]) * dt, "v": v, "y": y}


def _halves(v, y, dt):
    n = v.shape[0] // 2
    return _rec(v[:n], y[:n], dt), _rec(v[n : 2 * n], y[n : 2 * n], dt)


def real_cases(root: Path, *, stiction_loops: int | None = None) -> dict:
    """`{name: (estimation, validation, literature note)}` for every usable dataset
    under `root` (datasets that are missing are skipped)."""
    root = Path(root)
    out = {}

    def have(*parts):
        return (root.joinpath(*parts)).is_file()

    if have("cascaded_tanks", "estimation.csv"):
        e, t = (
            _csv(root / "cascaded_tanks/estimation.csv"),
            _csv(root / "cascaded_tanks/test.csv"),
        )
        out["cascaded_tanks"] = (
            _rec(e["u"], e["y"], 4.0),
            _rec(t["u"], t["y"], 4.0),
            "overflow = hard saturation, sqrt outflow, unknown initial state",
        )
    if have("ced_coupled_drives", "DATAPRBS.csv"):
        c = _csv(root / "ced_coupled_drives/DATAPRBS.csv")
        out["ced_prbs"] = (
            _rec(c["u2"], c["z2"], 0.02),  # the +-1.5 record
            _rec(c["u1"], c["z1"], 0.02),  # the +-1.0 record
            "sensor measures |speed| (output absolute value), lightly damped",
        )
    if have("emps", "DATA_EMPS.csv") and have("emps", "DATA_EMPS_PULSES.csv"):
        e = _csv(root / "emps/DATA_EMPS.csv")
        p = _csv(root / "emps/DATA_EMPS_PULSES.csv")
        dt = float(e["t"][1] - e["t"][0]) * 10
        out["emps"] = (
            _rec(e["vir"][:80000:10][:800], e["qm"][:80000:10][:800], dt),
            _rec(p["vir"][:80000:10][:800], p["qm"][:80000:10][:800], dt),
            "asymmetric Coulomb + viscous friction, offset, integrator, closed loop",
        )
    if have("silverbox", "silverbox_uy.csv"):
        s = _csv(root / "silverbox/silverbox_uy.csv")
        dt = float(s["t"][1] - s["t"][0])
        # the multisine part [40650:127400]: its first 75 % trains, the rest tests
        start, stop = 40650, 127400
        cut = start + (3 * (stop - start)) // 4
        out["silverbox"] = (
            _rec(s["u"][start:cut], s["y"][start:cut], dt),
            _rec(s["u"][cut:stop], s["y"][cut:stop], dt),
            "cubic stiffness in feedback (Duffing): a feedback nonlinearity",
        )
    for name, folder, file, cols, dt, note in (
        (
            "ball_beam",
            "daisy_ball_beam",
            "ball-and-beam.csv",
            ("u", "y"),
            0.1,
            "none listed",
        ),
        (
            "heat_exchanger",
            "daisy_heat_exchanger",
            "exchanger.csv",
            ("q", "th"),
            1.0,
            "nonlinear, non-minimum phase",
        ),
        (
            "robot_arm",
            "daisy_robot_arm",
            "robot-arm.csv",
            ("u", "y"),
            1.0,
            "none listed",
        ),
    ):
        if have(folder, file):
            d = _csv(root / folder / file)
            est, val = _halves(d[cols[0]], d[cols[1]], dt)
            out[name] = (est, val, note)
    f16 = root / "f16_gvt"
    level3, level2 = (
        f16 / "F16Data_FullMSine_Level3.csv",
        f16 / "F16Data_FullMSine_Level2_Validation.csv",
    )
    if level3.is_file() and level2.is_file():
        # standard split: estimate on level 3, test on level 2; the second of the
        # 9 periods of 8192 samples (the first holds transients), block-averaged
        # by 8 (400 -> 50 Hz; the multisine spans 2-15 Hz)
        def period(path):
            x = _f16_columns(path)
            seg = slice(8192, 2 * 8192)
            return [c[seg].reshape(-1, 8).mean(axis=1) for c in x]

        (fe, ae), (fv, av) = period(level3), period(level2)
        out["f16_level3_to_2"] = (
            _rec(fe, ae, 8 / 400),
            _rec(fv, av, 8 / 400),
            "clearance + friction at the payload interface, in feedback (not an "
            "input nonlinearity); about 10 modes in 2-15 Hz",
        )
    hsm = root / "hsm150_two_motor"
    for name, est_file, val_file in (
        ("hsm150_pos", "idf_pos_0.06_1.csv", "idf_pos_0.065_1.csv"),
        ("hsm150_neg", "idf_neg_0.04_1.csv", "idf_neg_0.045_1.csv"),
        ("hsm150_pos_to_neg", "idf_pos_0.06_1.csv", "idf_neg_0.04_1.csv"),
    ):
        if (hsm / est_file).is_file() and (hsm / val_file).is_file():
            # torque in -> velocity, from rest, 1 ms sampling decimated by 10
            e, v = _csv(hsm / est_file), _csv(hsm / val_file)
            out[name] = (
                _rec(e["torque_in"][::10], e["vel"][::10], 0.01),
                _rec(v["torque_in"][::10], v["vel"][::10], 0.01),
                "none documented; friction / asymmetric breakaway plausible "
                "(operating points of opposite sign), not confirmed",
            )
    index = root / "stiction_plant_loops" / "index.csv"
    if index.is_file():
        files = sorted((root / "stiction_plant_loops" / "csv").glob("loop_*.csv"))
        for f in files[:stiction_loops]:
            d = _csv(f)
            dt = float(d["t"][1] - d["t"][0]) if d["t"].shape[0] > 1 else 10.0
            est, val = _halves(d["op"], d["pv"], dt)
            if min(np.ptp(r[k]) for r in (est, val) for k in ("v", "y")) == 0:
                continue  # constant op, or a dead pv sensor (e.g. loops 062, 066)
            out[f"stiction_{f.stem}"] = (est, val, "label withheld")
    return out


def _centre(est: dict, val: dict) -> tuple[dict, dict]:
    """Subtract the estimation record's means of v and y from both records (the
    nominal structures have no offsets and simulate from rest; the validation
    record is shifted by the *estimation* means, so nothing is fitted on it)."""
    mv, my = float(np.mean(est["v"])), float(np.mean(est["y"]))
    return tuple({"t": r["t"], "v": r["v"] - mv, "y": r["y"] - my} for r in (est, val))


AT_REST = 0.05  # |y| over the first samples, as a fraction of the range of y
REST_SAMPLES = 5


def from_rest(est: dict, val: dict) -> bool:
    """Whether both records start with the output at rest at zero: its first
    `REST_SAMPLES` samples within `AT_REST` of its range of 0.

    The contract's simulations start from rest (zero state), so such records are
    already in the frame the nominal model simulates in, and centring them would
    move their starting point off zero (a velocity held at 0 by static friction
    before a torque step would start at minus its mean). Records that do not start
    at zero output are centred (`_centre`). The 5 % is a stated tolerance for
    "indistinguishable from zero at the start", fixed before any diagnosis was
    run with it, and applied to every dataset alike (no names)."""
    for r in (est, val):
        y = np.asarray(r["y"], float)
        if np.max(np.abs(y[:REST_SAMPLES])) > AT_REST * max(np.ptp(y), 1e-300):
            return False
    return True


def gap_records(est: dict, val: dict) -> tuple[dict, dict]:
    """The two records as the diagnosis gets them: unchanged when they start at
    rest (`from_rest`), otherwise centred on the estimation record's means."""
    return (est, val) if from_rest(est, val) else _centre(est, val)


def write_real_cases(root: Path, out: Path, **kwargs) -> dict:
    """Write each adapted dataset as a case folder `out/<name>/`; returns the notes."""
    notes = {}
    for name, (est, val, note) in real_cases(root, **kwargs).items():
        est, val = gap_records(est, val)
        write_csv(Path(out) / name / "estimation.csv", est)
        write_csv(Path(out) / name / "validation.csv", val)
        notes[name] = note
    return notes
