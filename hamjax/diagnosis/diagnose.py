"""`diagnose_gap`: where the sim-to-real gap lies, which effect causes it, how far it
shrinks once that effect is added (the contract `../shared/contracts/gap-case.md`)."""

import functools as ft
import math
from collections import defaultdict
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import equinox as eqx
import jax
import numpy as np

from .._runtime import host_cores
from ..models import DiscreteTransferFunction, Hammerstein, PiecewiseLinear
from .attribute import Attribution, Candidate, attribute, one_step_errors
from .decide import decide
from .layout import (
    NOMINAL_UNCERTAINTY,
    ONE_GROUP,
    bucket,
    describe_nominal,
    n_free_parameters,
    prepare,
)
from .locate import locate
from .noise_fit import compile_in_background
from .nominal_fit import INTEGRATING_ORDERS, ORDERS
from .probabilities import effective_samples, probabilities
from .schedule import CASES_PER_BATCH, batch_size, run_queue


class GapDiagnosis(eqx.Module):
    """The diagnosis of one case (validation-record arrays for the figures)."""

    effect: str
    gap_before: float
    gap_after: float
    noise_floor: float
    shrink: float
    ranking: list
    where: dict
    tests: dict
    gap_definition: str
    probabilities: dict
    t: np.ndarray
    v: np.ndarray
    y: np.ndarray
    y_nominal: np.ndarray
    y_augmented: np.ndarray
    residual_before: np.ndarray
    residual_after: np.ndarray


class DiagnosisNotFinite(ValueError):
    """Case `index` came out NaN or inf (an overflow): an error, never a diagnosis."""

    def __init__(self, index: int, what: str):
        super().__init__(
            f"the diagnosis is not finite ({what}): is the nominal model stable and "
            "are the records on a sensible scale?"
        )
        self.index = index


def _not_finite(d: GapDiagnosis) -> str | None:
    """The first non-finite number of `d` that a diagnosis stands on, or None."""
    for name in ("gap_before", "gap_after", "noise_floor"):
        x = getattr(d, name)
        if not np.isfinite(x):
            return f"{name} = {x}"
    for name in ("y_nominal", "y_augmented", "residual_before", "residual_after"):
        if not np.all(np.isfinite(getattr(d, name))):
            return f"{name} has NaN or inf"
    return None


# The decision rules: `attribute`'s cascade of tests (the default) and `decide`'s
# one held-out likelihood for every candidate.
RULES = {"cascade": attribute, "likelihood": decide}
DEFAULT_RULE = "cascade"


def _length_group(n: int) -> int:
    # The fits follow each record's own length (`fit.normal_equations`), so cases
    # up to ONE_GROUP samples share one padded length and one compilation; longer
    # ones are grouped by powers of two (their padding is memory, not time).
    return int(2 ** np.ceil(np.log2(bucket(n))))


def _group(n: int) -> int:
    """The length group of a case whose longer record has `n` samples."""
    return max(_length_group(n), ONE_GROUP)


@dataclass(frozen=True)
class Padding:
    """The padding of a run: the parameter-vector width and, per length group
    (`_group`), the padded record length. A case's numbers depend on its padding
    (XLA's tiling, hence rounding, follows the array shapes) and, in the last
    digits, on the cases batched with it: a run cut into blocks (`run_blocks`),
    each one call with the run's padding, has the same numbers whichever process
    diagnoses which block."""

    n_params: int
    lengths: tuple[tuple[int, int], ...]  # (length group, padded length), sorted


@ft.cache
def _fitted_n_params() -> int:
    """The widest nominal `nominal_fit.fit_nominal` fits: a piecewise-linear map
    and the highest order (a stable block of max `ORDERS`, or an integrating one,
    of max `INTEGRATING_ORDERS` + 1)."""
    n = max(max(ORDERS), max(INTEGRATING_ORDERS) + 1)
    lin = DiscreteTransferFunction(np.ones(n + 1), np.r_[1.0, np.zeros(n)], 1.0)
    plant = Hammerstein(PiecewiseLinear(k1=1.0, k2=1.0), lin)
    return n_free_parameters(plant, fitted=True)


def run_padding(cases: Iterable[tuple[Hammerstein | None, int]]) -> Padding:
    """The padding of a run of `cases`, `(nominal, n)` each, `n` the longer of the
    two records' lengths: what `diagnose_many` pads a call of these cases to. A
    nominal None (no model.json: fitted later by `nominal_fit.fit_nominal`)
    counts as the widest nominal that fit can return, so the padding depends on
    each case alone, never on a fit."""
    n_params, lengths = 0, {}
    for plant, n in cases:
        width = _fitted_n_params() if plant is None else n_free_parameters(plant)
        n_params = max(n_params, width)
        lengths[_group(n)] = max(lengths.get(_group(n), 0), _length_group(n))
    return Padding(n_params, tuple(sorted(lengths.items())))


# Cases per `diagnose_many` call of a run cut into blocks (`run_blocks`): each
# block's cases are batched together (`schedule.run_queue`), so a block of at
# least `CASES_PER_BATCH` cases keeps the batches full. Its cost, measured on 120
# A0 cases (1 process, 2 cores under a load of 12-17, old and new alternating
# twice): blocks of 32 took 333 and 319 s against 282 and 259 s for one call of
# all 120 (+20 %, 2.7 against 2.25 s per case), probably the tail of part-filled
# batches each call ends with (`schedule.run_queue`; not profiled). Quiet machine
# (load 1.6): 120 cases in blocks of 32 / 64 / one call 81 / 69 / 61 s; 240 cases
# in blocks of 128 105 s against one call 99 s (+6 %), hence 128.
CASES_PER_CALL = 128


def run_blocks(n_cases: int) -> list[range]:
    """The blocks of a run of `n_cases` cases, positions in the run's order (for
    `hamjax diagnose`, the case folders sorted by path): `CASES_PER_CALL`
    consecutive cases each, the last one shorter.

    Each block is one `diagnose_many` call with the run's padding (`run_padding`
    of all its cases). A case's numbers depend on its padding and on the cases
    batched with it, both fixed by the block, so they depend only on the run's
    case list, never on which process (or how many) diagnoses which block."""
    size = CASES_PER_CALL
    return [range(k, min(k + size, n_cases)) for k in range(0, n_cases, size)]


def _tried(att: Attribution) -> dict[str, tuple[float, np.ndarray]]:
    """Each class tried once, `none` included: its validation mean-square error and
    residual, the evidence of `probabilities`. Beside a fitted nominal a re-fit is
    no verdict, and `none` is the reference (the re-fit's when it is the
    reference: `attribute`).

    Named a noise model, the evidence is like for like: every deterministic
    candidate is seen through the named predictor as the cascade's tests through
    it see the class (`attribute.one_step_errors` of its prediction-error fit
    where one was made, `Attribution.whitened`), so its one-step-ahead errors,
    not its simulation errors, stand against the named model's (the `none`
    rival keeps the white-noise predictor, its simulation residual). The
    likelihood rule's noise models (`decide`: several parameters,
    `noise_model` among them) carry no one-step predictor
    (`Candidate.predictor`); there every rival keeps its own measure."""
    chosen = att.chosen
    through = chosen is not None and chosen.predictor is not None

    def seen(c: Candidate) -> tuple[float, np.ndarray]:
        if not (through and c.measure == "simulation"):
            return c.gap_after**2, c.residual
        r = att.whitened.get(c.effect, c).residual
        err = one_step_errors(chosen, r)
        if err is None:  # a failed fit
            return math.inf, r
        return float(np.mean(err**2)), err

    out = {"none": (att.gap_before**2, att.r_before)}
    for c in att.candidates:
        if att.fitted and c.effect == "parameter_mismatch":
            if att.reference == "refit":  # its simulation: the white-noise predictor
                out["none"] = (c.gap_after**2, c.residual)
        else:
            out[c.effect] = seen(c)
    return out


def _evidence_samples(att: Attribution, tried: dict) -> float:
    """`probabilities.effective_samples` of the named effect against its best
    rival (`tried`: `_tried(att)`)."""
    named = att.chosen.effect if att.chosen is not None else "none"
    rivals = [k for k in tried if k != named]
    if named not in tried or not rivals:
        return float(att.r_before.shape[0])
    rival = min(rivals, key=lambda k: tried[k][0])
    return effective_samples(tried[named][1], tried[rival][1])


def _evidence(att: Attribution) -> tuple[dict[str, float], float]:
    """`(mse, n_eff)`: each class tried once (`_tried`) with its validation mean
    square, and the effective samples of the named effect against its best
    rival: what `probabilities` reads."""
    tried = _tried(att)
    return {k: v[0] for k, v in tried.items()}, _evidence_samples(att, tried)


def attribution_probabilities(att: Attribution) -> dict[str, float]:
    """The stated probabilities of one case's attribution (`probabilities`), as
    `diagnosis.json` holds them."""
    return probabilities(att.effect, *_evidence(att), att.shrink)


def _result(prep, att: Attribution, val: dict) -> GapDiagnosis:
    chosen = att.chosen
    if chosen is None:
        y_aug, r_after = att.y_nominal, att.r_before
    elif chosen.prediction is None:  # noise model: the one-step-ahead predictor
        r_after = chosen.residual
        y_aug = val["y"] - r_after
    else:
        y_aug, r_after = chosen.prediction, chosen.residual
    noise = chosen is not None and chosen.measure == "one_step_prediction"
    base = (
        "the re-fitted nominal's simulation (it improves significantly on "
        "hamjax's own nominal fit)"
        if att.reference == "refit"
        else "nominal simulation"
    )
    definition = (
        f"one-step-ahead prediction error ({base} + fitted noise/trend predictor; "
        "gap_before with the white-noise predictor)"
        if noise
        else "simulation error from rest on the validation record"
    )
    ranking = [
        {
            "effect": c.effect,
            "gap_after": c.gap_after,
            "measure": c.measure,
            "params": c.params,
        }
        for c in att.candidates
    ]
    where = locate(
        val["t"],
        val["v"],
        att.r_before,
        r_after,
        prep.u_val,
        att.noise_floor,
        prep.ctx.dt,
        y=val["y"],
        v_est=np.asarray(prep.arrays.v_est)[: prep.n_est],
    )
    mse, n_eff = _evidence(att)
    return GapDiagnosis(
        effect=att.effect,
        probabilities=probabilities(att.effect, mse, n_eff, att.shrink),
        gap_before=att.gap_before,
        gap_after=att.gap_after,
        noise_floor=att.noise_floor,
        shrink=att.shrink,
        ranking=ranking,
        where=where,
        tests=att.tests
        | {
            "nominal_prior": {"weight": float(prep.arrays.prior_weight)},
            "evidence": {
                "samples": len(val["y"]),
                "effective_samples": n_eff,
                # each class's validation mean square `probabilities` read
                # (written null where infinite)
                "mse": {k: float(v) for k, v in mse.items()},
            },
        },
        gap_definition=definition,
        t=val["t"],
        v=val["v"],
        y=val["y"],
        y_nominal=att.y_nominal,
        y_augmented=np.asarray(y_aug),
        residual_before=att.r_before,
        residual_after=np.asarray(r_after),
    )


def diagnose_many(
    items: list[tuple[Hammerstein, float, dict, dict]],
    *,
    cases_per_batch: int = CASES_PER_BATCH,
    on_result: Callable[[int, GapDiagnosis], None] | None = None,
    nominal_uncertainty: float | None = NOMINAL_UNCERTAINTY,
    rule: str = DEFAULT_RULE,
    padding: Padding | None = None,
    fitted: Sequence[bool] | None = None,
) -> list[GapDiagnosis]:
    """Diagnose several cases: `(plant, dt, estimation, validation)` each, the records
    being `{"t", "v", "y"}` dicts of NumPy arrays.

    Cases are padded to a common length (records over `ONE_GROUP` samples to a
    few) and taken in order of map kind and length, so that a batch holds cases
    alike; per length, their candidate rows go through one compiled batch
    (`schedule.run_queue`) of the screening rows of `cases_per_batch` cases,
    split over the devices. Every re-fit of the nominal parameters is a
    maximum-a-posteriori fit under a Gaussian prior at nominal of relative std
    `nominal_uncertainty` (`layout.prior_weight`; None: a negligible prior).
    `rule` names the decision (`RULES`: "cascade", `attribute.attribute`;
    "likelihood", `decide.decide`). `on_result(i, diagnosis)` is
    called as soon as case `i` is done, so a caller can write each result while the
    others are still being fitted. `padding`: that of a whole run (`run_padding`
    of all its cases), for a call of one block of it (`run_blocks`); None:
    `run_padding(items)`. `fitted[i]`: case `i`'s nominal is hamjax's own fit
    (`nominal_fit.fit_nominal`, no model.json; `layout.prepare(fitted_nominal=)`);
    None: no case's.

    **Raises:** `DiagnosisNotFinite` (its `index` the case) if a case's gaps, noise
    floor or simulated outputs are NaN or inf.
    """
    if not jax.config.jax_enable_x64:
        # float32 fits stop early and at other minima: different, worse diagnoses
        raise RuntimeError(
            "the diagnosis needs float64: call hamjax.enable_x64() (or set "
            "JAX_ENABLE_X64=1) before the first JAX computation"
        )
    if rule not in RULES:
        raise ValueError(f"unknown rule {rule!r}: one of {sorted(RULES)}")
    name_effect = RULES[rule]
    lengths = [max(est["v"].shape[0], val["v"].shape[0]) for *_, est, val in items]
    kinds = [describe_nominal(plant).nl_kind for plant, *_ in items]
    groups = defaultdict(list)
    # Cases alike in a batch (`fit._fit_flat`): by map kind, then by length.
    for i in sorted(range(len(items)), key=lambda i: (kinds[i], lengths[i])):
        groups[_group(lengths[i])].append(i)
    fitted = [False] * len(items) if fitted is None else [bool(f) for f in fitted]
    if len(fitted) != len(items):
        raise ValueError(f"{len(fitted)} `fitted` flags for {len(items)} cases")
    # a fitted nominal counts as the widest fit (as a case without model.json does)
    own = run_padding(
        (None if f else plant, n)
        for (plant, *_), n, f in zip(items, lengths, fitted, strict=True)
    )
    padding = padding or own
    n_params, padded = padding.n_params, dict(padding.lengths)
    if n_params < own.n_params or any(padded.get(g, 0) < n for g, n in own.lengths):
        raise ValueError(f"the cases do not fit in {padding} (run_padding: {own})")
    # the noise models compile while the fits do (once per call)
    overlap = ft.cache(ft.partial(compile_in_background, lengths))
    out: list = [None] * len(items)
    for group, members in groups.items():
        # one case per core at a time: `prepare`'s heavy work (the stick-slip
        # profile's scans, filters and products) runs outside the GIL, and each
        # case's rows are its own, the same on any number of threads
        one = ft.partial(
            _prepare_one, items, padded[group], n_params, nominal_uncertainty, fitted
        )
        with ThreadPoolExecutor(min(host_cores(), len(members))) as pool:
            preps = list(pool.map(one, members))

        def finished(j: int, fit: dict, preps=preps, members=members) -> None:
            i = members[j]
            out[i] = _result(preps[j], name_effect(preps[j], fit), items[i][3])
            bad = _not_finite(out[i])
            if bad is not None:
                raise DiagnosisNotFinite(i, bad)
            if on_result is not None:
                on_result(i, out[i])

        run_queue(preps, batch_size(preps, cases_per_batch), finished, overlap)
    return out


def _prepare_one(items, length, n_params, nominal_uncertainty, fitted, i):
    """`layout.prepare` of case `i` of `diagnose_many`'s `items`."""
    return prepare(
        *items[i],
        length,
        n_params,
        nominal_uncertainty=nominal_uncertainty,
        fitted_nominal=fitted[i],
    )


def diagnose_gap(
    plant: Hammerstein,
    dt: float,
    estimation: dict,
    validation: dict,
    *,
    nominal_uncertainty: float | None = NOMINAL_UNCERTAINTY,
    rule: str = DEFAULT_RULE,
    fitted: bool = False,
) -> GapDiagnosis:
    """Diagnose the gap between `plant` (the nominal model) and two records.

    **Arguments:**

    - `plant`: nominal Hammerstein model (identity, piecewise-linear or tabulated
      map; discrete or continuous linear block of order <= 4).
    - `dt`: sampling period (s).
    - `estimation`, `validation`: `{"t", "v", "y"}` dicts of NumPy arrays, two
      separate experiments; effects are fitted on the first, scored on the second.

    - `nominal_uncertainty`: relative std of the nominal parameters (the prior of
      every re-fit; default 0.2).
    - `rule`: the decision rule, "cascade" (default) or "likelihood" (`RULES`).
    - `fitted`: `plant` is `nominal_fit.fit_nominal`'s (the case has no model.json).

    **Returns:** a `GapDiagnosis` (the contract's fields and the figure data).
    """
    return diagnose_many(
        [(plant, dt, estimation, validation)],
        nominal_uncertainty=nominal_uncertainty,
        rule=rule,
        fitted=[fitted],
    )[0]
