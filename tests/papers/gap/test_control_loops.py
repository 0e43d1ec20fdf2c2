"""The control-loop benchmark (papers/gap/control_loops.py, issue 19)."""

from collections import Counter

import numpy as np
import pytest
from helpers import run_hamjax, tree_hash
from scipy import signal

from hamjax.diagnosis.case import read_case
from hamjax.diagnosis.layout import N_MAX
from hamjax.io import load_model, read_json, write_json
from hamjax.papers.gap import control_loops as cl
from hamjax.papers.gap.blind import STICTION_LIKE, TRUTH_CLASSES, format_score, score


# ------------------------------------------------------------ stiction ------


def test_choudhury_on_a_ramp_up_down_with_a_stop():
    # The definition (Choudhury et al. 2005): at rest the input must move more than S
    # from where the valve stuck (x_ss) to slip, more than J when it restarts in the
    # same direction after a stop; moving, y = x - sign(dx) (S - J)/2.
    S, J, a = 0.5, 0.25, 0.125  # binary fractions: exact comparisons
    off = (S - J) / 2
    up = a * np.arange(17)  # k 0-16: 0 .. 2
    down = 2.0 - a * np.arange(1, 6)  # k 17-21: 1.875 .. 1.375
    hold = np.full(3, 1.375)  # k 22-24: stops
    down2 = 1.375 - a * np.arange(1, 5)  # k 25-28: 1.25 .. 0.875
    x = np.concatenate([up, down, hold, down2])
    y = cl.valve_positions(cl.ChoudhuryStiction(S, J), x)
    expected = np.concatenate(
        [
            np.zeros(5),  # stuck at rest until x - 0 > S: x = 0.625 (k 5)
            up[5:] - off,  # moving up
            np.full(4, 2.0 - off),  # reversed at x_ss = 2: stuck until 2 - x > S
            [1.375 + off],  # slips at x = 1.375: a jump of J + a (the overshoot)
            np.full(3, 1.375 + off),  # stopped at x_ss = 1.375
            np.full(2, 1.375 + off),  # restart, same direction: 1.375 - x <= J
            [1.0 + off, 0.875 + off],  # x = 1.0: 0.375 > J, slips and moves on
        ]
    )
    np.testing.assert_array_equal(y, expected)
    assert (2.0 - off) - y[21] == J + a


def test_choudhury_stop_then_restart_needs_only_j():
    S, J = 0.5, 0.25
    x = np.array([0.0, 0.6, 0.7, 0.7, 0.7, 0.8, 0.9, 0.96, 1.0])
    y = cl.valve_positions(cl.ChoudhuryStiction(S, J), x)
    off = (S - J) / 2
    assert y[1] == pytest.approx(0.6 - off)  # crossed S from rest
    assert y[2] == pytest.approx(0.7 - off)  # moving
    # stopped at x_ss = 0.7: restarting upwards it slips once x - 0.7 > J
    assert np.all(y[3:7] == y[2])
    assert y[7] == pytest.approx(0.96 - off)
    assert y[8] == pytest.approx(1.0 - off)


def test_he_on_a_ramp_is_stick_slip():
    # He et al. (2007): temp = u_r + dx; |temp| > fs slips with u_r = sign(temp) fd,
    # else u_r = temp; y = x - u_r. On a ramp of slope a from rest the valve first
    # moves at the first k with k a > fs (to k a - fd), then after every m samples,
    # m the first integer with m a + fd > fs, each time to x - fd.
    fs, fd, a = 0.5, 0.25, 0.125
    x = a * np.arange(40)
    y = cl.valve_positions(cl.HeStiction(fs, fd), x)
    k1 = int(np.floor(fs / a)) + 1
    m = int(np.floor((fs - fd) / a)) + 1
    slips = list(range(k1, 40, m))
    expected = np.zeros(40)
    for k in range(40):
        last = [s for s in slips if s <= k]
        expected[k] = x[last[-1]] - fd if last else 0.0
    np.testing.assert_allclose(y, expected, rtol=0, atol=1e-15)
    # each slip jumps by m a (the stick band fs - fd plus the overshoot)
    jumps = np.diff(y)[np.diff(y) > 0]
    assert np.allclose(jumps[1:], m * a)


def test_he_reversal_needs_fs_plus_fd():
    fs, fd = 0.5, 0.2
    x = np.concatenate([np.linspace(0, 2, 21), 2 - np.linspace(0.05, 1, 20)])
    y = cl.valve_positions(cl.HeStiction(fs, fd), x)
    top = y[20]
    back = np.nonzero(y[21:] < top)[0][0] + 21  # the first downward move
    # it stayed while 2 - x <= fs + fd (u_r ran from +fd down to -fs)
    assert 2 - x[back] > fs + fd - 1e-12 and 2 - x[back - 1] <= fs + fd + 1e-12
    assert y[back] == pytest.approx(x[back] + fd)


# -------------------------------------------------------------- loops -------


@pytest.mark.parametrize("kind", cl.PROCESSES)
def test_discrete_process_matches_scipy_zoh(kind):
    rng = np.random.default_rng([9, cl.PROCESSES.index(kind)])
    dt = 2.0
    p, _ = cl._physics(rng, kind, dt)
    num, den = cl.process_tf(kind, p)
    b, a = cl.discrete_process(num, den, dt, 2)
    bz, az, _ = signal.cont2discrete((num, den), dt, method="zoh")
    u = rng.standard_normal(300)
    ref = signal.lfilter(np.ravel(bz), az, u)
    ref = np.concatenate([np.zeros(2), ref[:-2]])  # two samples of dead time
    np.testing.assert_allclose(signal.lfilter(b, a, u), ref, atol=1e-9 * _scale(ref))


def _scale(x):
    return max(float(np.max(np.abs(x))), 1e-300)


@pytest.mark.parametrize("kind", cl.PROCESSES)
def test_loop_closes_without_stiction(kind):
    # noise-free, no stiction: the PI integrator takes PV to each setpoint
    # (steady-state error -> 0), and the recorded PV is B/A OP exactly.
    rng = np.random.default_rng([7, cl.PROCESSES.index(kind)])
    dt = 5.0
    p, delay = cl._physics(rng, kind, dt)
    b, a = cl.discrete_process(*cl.process_tf(kind, p), dt, delay)
    pi = cl.simc_pi(kind, p, delay, dt, detune=2.0)
    n = 8000
    sp = np.where(np.arange(n) < 4000, 2.0, -1.0)
    lp = cl.simulate_loop(b, a, pi, dt, sp, np.zeros(n), np.zeros(n))
    assert abs(lp["pv"][3999] - 2.0) < 1e-8 and abs(lp["pv"][-1] + 1.0) < 1e-8
    # ... and the error is on its way to 0, not a steady offset
    assert abs(lp["pv"][3999] - 2.0) < 1e-3 * abs(lp["pv"][2000] - 2.0) + 1e-13
    np.testing.assert_allclose(
        lp["pv"], signal.lfilter(b, a, lp["op"]), atol=1e-10 * _scale(lp["pv"])
    )


@pytest.mark.parametrize("model", ["choudhury", "he"])
def test_stiction_makes_an_integrating_loop_cycle(model):
    # the classic signature: an integrating process under PI with a sticky valve
    # keeps oscillating at a constant setpoint, noise-free, while the same loop
    # without stiction settles.
    rng = np.random.default_rng([5, 1])
    dt = 1.0
    p, delay = cl._physics(rng, "integrating", dt)
    b, a = cl.discrete_process(*cl.process_tf("integrating", p), dt, delay)
    pi = cl.simc_pi("integrating", p, delay, dt, detune=1.5)
    n = 8000
    sp, zero = np.ones(n), np.zeros(n)
    st = {"model": model, "S": 2.0, "J": 0.5, "fs": 1.25, "fd": 0.75}
    lp = cl.simulate_loop(b, a, pi, dt, sp, zero, zero, valve=cl.make_valve(st))
    free = cl.simulate_loop(b, a, pi, dt, sp, zero, zero)
    err = lp["pv"] - sp
    late, mid = err[6000:], err[4000:6000]
    crossings = np.count_nonzero(np.diff(np.sign(late - late.mean())) != 0)
    assert crossings >= 6  # at least three periods in the last 2000 samples
    assert 0.5 < np.std(late) / np.std(mid) < 2.0  # sustained, not decaying
    assert np.std(late) > 1e-3
    assert np.std(free["pv"][6000:] - 1.0) < 1e-8
    # the valve sticks: it holds its position for runs of samples while OP moves
    held = np.count_nonzero(np.diff(lp["x"][6000:]) == 0)
    assert held > 0.3 * 2000


# ------------------------------------------------------------- the set ------


@pytest.fixture(scope="module")
def loops(tmp_path_factory):
    out = tmp_path_factory.mktemp("loops")
    return out, cl.make_cases(0, 16, out)


def test_balanced_blocks():
    slots = cl.slots_for(3, 5 * len(cl.SLOTS))
    for b in range(5):
        block = slots[b * len(cl.SLOTS) : (b + 1) * len(cl.SLOTS)]
        assert sorted(block, key=str) == sorted(cl.SLOTS, key=str)
        assert sum(label == "backlash" for label, _ in block) == len(cl.SLOTS) // 2
    assert set(cl.LABELS) <= set(TRUTH_CLASSES)
    assert cl.MAX_ORDER == N_MAX  # the dead time keeps what the diagnosis reads


def test_cases_are_readable_loop_records(loops):
    out, truth = loops
    assert truth["family"] == "loops"
    counts = Counter(tr["effect"] for tr in truth["cases"].values())
    assert counts["backlash"] == 8
    for name, tr in truth["cases"].items():
        folder = out / "cases" / name
        case = read_case(folder)  # what `hamjax diagnose` reads
        plant, dt = load_model(folder / "model.json")
        assert dt == tr["dt"] and tr["dt"] in cl.DTS
        assert case.model is not None and plant.linear.is_stable()
        n = case.estimation["t"].shape[0]
        assert cl.N_SAMPLES[0] <= n <= cl.N_SAMPLES[1]
        assert (tr["stiction"] is not None) == (tr["effect"] == "backlash")
        errs = np.abs(list(tr["nominal_errors"].values()))
        if tr["effect"] in ("backlash", "parameter_mismatch"):
            assert np.all((errs >= 0.15 - 1e-12) & (errs <= 0.20 + 1e-12))
        else:
            assert tr["nominal_gap_over_noise"] <= 0.1 + 1e-9
        if tr["effect"] == "parameter_mismatch":
            assert tr["nominal_gap_over_noise"] >= 0.3 - 1e-9
        assert (tr["valve_gap_rms"] > 0) == (tr["effect"] == "backlash")
        # what the valve adds to the PV, over the noise and disturbance; 0 (to
        # rounding of the filter) without a sticky valve
        assert (tr["valve_visibility"] > 1e-9) == (tr["effect"] == "backlash")


def test_none_loop_is_the_nominal_plus_white_noise(loops):
    # y - B/A v for a `none` loop: the noise (std sigma) plus a nominal error of at
    # most 0.1 sigma; with n >= 1000 the sample std's relative error is about
    # 1/sqrt(2n) <= 2.3 %, so 0.88-1.12 is > 4 of them beyond the nominal's share.
    out, truth = loops
    checked = 0
    for name, tr in truth["cases"].items():
        if tr["effect"] != "none":
            continue
        model = load_model(out / "cases" / name / "model.json")[0].linear
        case = read_case(out / "cases" / name)
        for rec in (case.estimation, case.validation):
            r = rec["y"] - signal.lfilter(
                np.asarray(model.b), np.asarray(model.a), rec["v"]
            )
            assert 0.88 < np.std(r) / tr["noise_std"] < 1.12
            rho = np.corrcoef(r[1:], r[:-1])[0, 1]
            assert abs(rho) < 0.15  # white: 4.7 x 1/sqrt(1000) covers the nominal
        checked += 1
    assert checked == 2


def test_valve_visibility_from_the_published_records(loops):
    # the truth's valve visibility rebuilt from what a user has: the written
    # records (OP, PV), the truth's process (`discrete_process`) and its valve
    # replayed on OP by the published model (`make_valve`): RMS(G x - G OP) /
    # RMS(PV - G x), the smaller of the two records. The CSV's rounding of the
    # records bounds the agreement (to 1e-6 relative)
    out, truth = loops
    checked = 0
    for name, tr in truth["cases"].items():
        if tr["effect"] != "backlash":
            continue
        b, a = cl.discrete_process(
            *cl.process_tf(tr["process"], tr["physics"]), tr["dt"], tr["delay_samples"]
        )
        case = read_case(out / "cases" / name)
        found = []
        for rec in (case.estimation, case.validation):
            x = cl.valve_positions(cl.make_valve(tr["stiction"]), rec["v"])
            w = signal.lfilter(b, a, x)
            added = w - signal.lfilter(b, a, rec["v"])
            found.append(np.sqrt(np.mean(added**2) / np.mean((rec["y"] - w) ** 2)))
        assert np.isclose(min(found), tr["valve_visibility"], rtol=1e-6), name
        checked += 1
    assert checked == 8


def test_case_independent_of_the_count_and_deterministic(loops, tmp_path):
    out, truth = loops
    fewer = cl.make_cases(0, 3, tmp_path / "fewer")
    for name in fewer["cases"]:
        for f in ("model.json", "estimation.csv", "validation.csv"):
            a = (tmp_path / "fewer" / "cases" / name / f).read_bytes()
            assert a == (out / "cases" / name / f).read_bytes()
        assert fewer["cases"][name] == truth["cases"][name]
    again = cl.make_cases(0, 3, tmp_path / "again")
    assert tree_hash(tmp_path / "again") == tree_hash(tmp_path / "fewer")
    assert again == fewer
    assert cl.make_cases(1, 3, tmp_path / "other")["cases"] != fewer["cases"]


# ------------------------------------------------------------- scoring ------


def test_stiction_scores():
    effects = ["backlash"] * 4 + [
        "none",
        "parameter_mismatch",
        "drift",
        "coloured_noise",
    ]
    named = ["backlash", "dead_zone", "none", "backlash"]
    named += ["none", "friction", "drift", "preload"]
    truth = {
        "family": "loops",
        "cases": {
            f"c{i}": {"effect": e, "noise_std": 1.0} for i, e in enumerate(effects)
        },
    }
    names = {f"c{i}": p for i, p in enumerate(named)}
    kinds = ["fopdt", "integrating", "integrating", "sopdt"]
    dists = [None, "drift", None, "coloured"]
    vis = [0.5, 1.0, 2.9, 3.0]
    for i, (kind, dist, v) in enumerate(zip(kinds, dists, vis, strict=True)):
        truth["cases"][f"c{i}"] |= {
            "process": kind,
            "disturbance": dist,
            "valve_visibility": v,
        }
    s = score(truth, names)
    st = s["stiction"]
    # by process: the integrating loops c1 (dead_zone) and c2 (none), 1 of 2;
    # by disturbance: c0 and c2 have none (1 of 2), c1 drift, c3 coloured; by
    # visibility: the band's lower edge belongs to it (1.0 and 3.0)
    assert st["recall_by"] == {
        "process": {"fopdt": [1, 1], "integrating": [1, 2], "sopdt": [1, 1]},
        "disturbance": {"coloured": [1, 1], "drift": [1, 1], "none": [1, 2]},
        "valve_visibility": {"<1": [1, 1], "1-3": [1, 2], ">=3": [1, 1]},
    }
    assert list(st["recall_by"]["valve_visibility"]) == ["<1", "1-3", ">=3"]
    assert "stiction recall by process: fopdt 1.000 (1/1), integrating 0.500 (1/2)" in (
        format_score(s)
    )
    # recall: 3 of 4 stiction loops named stiction-like (backlash twice, dead_zone),
    # 2 of 4 named backlash itself; false alarm: friction and preload on 2 of the 4
    # loops without stiction
    assert st["recall"] == 0.75 and st["false_alarm"] == 0.5
    assert st["recall_backlash"] == 0.5
    assert st["balanced_accuracy"] == 0.625
    assert {"friction", "preload", "dead_zone", "backlash"} == set(STICTION_LIKE)
    assert "stiction: recall 0.750 (of 4; named backlash itself 0.500)" in (
        format_score(s)
    )
    names["c2"], names["c5"] = "friction", "unexplained"
    st = score(truth, names)["stiction"]
    assert (st["recall"], st["false_alarm"]) == (1.0, 0.25)
    assert st["recall_backlash"] == 0.5
    assert st["balanced_accuracy"] == 0.875
    truth["family"] = "B"
    assert score(truth, names)["stiction"] is None


def test_cli_make_and_score_loops(tmp_path):
    out = tmp_path / "L"
    r = run_hamjax(
        "blind",
        "make",
        "--family",
        "loops",
        "--cases",
        "2",
        "--seed",
        "3",
        "--out",
        str(out),
    )
    assert r.returncode == 0, r.stderr
    truth = read_json(out / "truth.json")
    assert truth == cl.make_cases(3, 2, tmp_path / "direct")
    res = tmp_path / "R"
    for name, tr in truth["cases"].items():  # a diagnosis that names the truth
        write_json(
            res / name / "diagnosis.json",
            {"effect": tr["effect"], "gap_before": 1.0, "gap_after": 1.0},
        )
    r = run_hamjax("blind", "score", str(out), str(res))
    assert r.returncode == 0, r.stderr
    assert "stiction: recall" in r.stdout
    s = read_json(res / "score.json")
    assert (
        s["accuracy"] == 1.0
        and s["stiction"]["n_stiction"] + s["stiction"]["n_without"] == 2
    )
    r = run_hamjax(
        "blind",
        "make",
        "--family",
        "loops",
        "--realism",
        "exact",
        "--cases",
        "1",
        "--out",
        str(tmp_path / "X"),
    )
    assert r.returncode == 2 and "family A only" in r.stderr
