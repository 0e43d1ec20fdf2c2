"""`diagnose_gap`: where the sim-to-real gap lies, which effect causes it, how far it
shrinks once that effect is added (the contract `../shared/contracts/gap-case.md`)."""

from collections import defaultdict
from collections.abc import Callable

import equinox as eqx
import jax
import jax.tree_util as jtu
import numpy as np

from ..models import Hammerstein
from ..montecarlo.sharding import effective_chunk
from .attribute import Attribution, attribute
from .fit import fit_cases
from .layout import bucket, n_free_parameters, prepare
from .locate import locate


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
    t: np.ndarray
    v: np.ndarray
    y: np.ndarray
    y_nominal: np.ndarray
    y_augmented: np.ndarray
    residual_before: np.ndarray
    residual_after: np.ndarray


def _length_group(n: int) -> int:
    # coarse groups (powers of two) so a batch of cases compiles only a few times
    b = bucket(n)
    return int(2 ** np.ceil(np.log2(b)))


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
    definition = (
        "one-step-ahead prediction error (nominal simulation + fitted noise/trend "
        "predictor; gap_before with the white-noise predictor)"
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
    )
    return GapDiagnosis(
        effect=att.effect,
        gap_before=att.gap_before,
        gap_after=att.gap_after,
        noise_floor=att.noise_floor,
        shrink=att.shrink,
        ranking=ranking,
        where=where,
        tests=att.tests,
        gap_definition=definition,
        t=val["t"],
        v=val["v"],
        y=val["y"],
        y_nominal=att.y_nominal,
        y_augmented=np.asarray(y_aug),
        residual_before=att.r_before,
        residual_after=np.asarray(r_after),
    )


REFIT = "parameter_mismatch"
# Levenberg-Marquardt budget. Every row gets MAIN_STEPS (a screening: enough to
# rank the starts and classes), the rows the decision rests on get CONTINUE_STEPS
# more (`_continue_stopped`). On the seed-100 exact benchmark, 30 + 120 steps and
# 8 + 40 steps named the same effects in 240 of 240 cases, at 231 s and 117 s.
MAIN_STEPS = 8
CONTINUE_STEPS = 40
CONTINUE_CLASSES = 4
RESTART = 1  # column of the finishing batch that restarts the re-fit


def _continue_stopped(padded: list, rows, cases, fits, *, reuse_shape: bool = False):
    """Finish the rows the decision rests on, per case (one `[case, column]` batch).

    - The re-fit row (`parameter_mismatch`), continued if it stopped at the step
      limit: it is the reference every structural candidate is tested against,
      so an unfinished one lets a structural row look significant.
    - The re-fit row again, restarted from the nominal parameters of the best
      structural row. The re-fit is nested in every structural candidate (each
      is neutral at its neutral parameters), so a structural row that ends far
      below it often marks a local minimum of the re-fit from the nominal start
      rather than an effect; the restart finds the re-fit's better minimum
      (kept only if its estimation SSE is lower).
    - The best rows of the `CONTINUE_CLASSES` leading structural classes (by
      estimation SSE), continued if they stopped: an unfinished row of the true
      effect lets another effect win. Classes further down were measured not to
      change the decision on the development benchmark, and continuing every
      class doubled the cost.

    With `reuse_shape` the batch is padded to the main fit's `[case, row]` shape, so
    the compiled main fit is reused: cheaper than a second compilation (~8 s) when
    there are only a few cases.
    """
    result = np.asarray(fits.result)
    sse = np.where(np.isfinite(fits.sse_est), fits.sse_est, np.inf)
    theta = np.asarray(fits.theta)
    width = effective_chunk(2 + CONTINUE_CLASSES, jax.device_count())
    if reuse_shape:
        width = max(width, rows.theta0.shape[1])
    pick, start = [], []
    for c, p in enumerate(padded):
        names = [name for name, _ in p.rows]
        best = {}
        for k, name in enumerate(names):
            if name not in best or sse[c, k] < sse[c, best[name]]:
                best[name] = k
        i_pm = best.pop(REFIT)
        lead = sorted(best.values(), key=lambda k: sse[c, k])[:CONTINUE_CLASSES]
        used = np.asarray(p.rows[i_pm][1].idx) < p.arrays.anchor.shape[0]
        columns = [i_pm, i_pm] + lead + [i_pm] * (width - 2 - len(lead))
        pick.append(columns)
        starts = [theta[c, k] for k in columns]
        starts[RESTART] = np.where(used, theta[c, lead[0]], 0.0)  # nominal part only
        start.append(starts)
    pick, start = np.asarray(pick), np.asarray(start)
    cidx = np.arange(len(padded))[:, None]
    sel = jtu.tree_map(lambda x: np.asarray(x)[cidx, pick], rows)
    sel = eqx.tree_at(lambda r: r.theta0, sel, start)
    more = jtu.tree_map(np.asarray, fit_cases(sel, cases, CONTINUE_STEPS))
    more_sse = np.where(np.isfinite(more.sse_est), more.sse_est, np.inf)
    out = jtu.tree_map(np.array, fits)
    for c in range(len(padded)):
        for j in range(width):
            k = pick[c, j]
            if j == RESTART:
                take = more_sse[c, j] < out.sse_est[c, k]
            else:
                take = result[c, k] != 0 and more_sse[c, j] <= out.sse_est[c, k]
            if take:
                for name in fits.__dataclass_fields__:
                    getattr(out, name)[c, k] = getattr(more, name)[c, j]
    return out


def diagnose_many(
    items: list[tuple[Hammerstein, float, dict, dict]],
    *,
    chunk: int = 8,
    on_result: Callable[[int, GapDiagnosis], None] | None = None,
) -> list[GapDiagnosis]:
    """Diagnose several cases: `(plant, dt, estimation, validation)` each, the records
    being `{"t", "v", "y"}` dicts of NumPy arrays.

    Cases are padded to a few common lengths and fitted together (`vmap` over cases
    and candidate rows), `chunk` cases per call of the one compiled function (a
    multiple of the device count; the chunk is split over the devices).
    `on_result(i, diagnosis)` is called as soon as case `i` is done, so a caller
    can write each result before the next chunk starts.
    """
    chunk = effective_chunk(chunk, jax.device_count())
    groups = defaultdict(list)
    for i, (_plant, _dt, est, val) in enumerate(items):
        n = max(est["v"].shape[0], val["v"].shape[0])
        groups[_length_group(n)].append(i)
    n_params = max(n_free_parameters(plant) for plant, *_ in items)
    out: list = [None] * len(items)
    for length, members in groups.items():
        for start in range(0, len(members), chunk):
            part = members[start : start + chunk]
            preps = [
                prepare(
                    items[i][0], items[i][1], items[i][2], items[i][3], length, n_params
                )
                for i in part
            ]
            # pad the chunk to `chunk` cases with copies so the shape never changes
            padded = (
                preps + [preps[-1]] * (chunk - len(preps)) if len(items) > 1 else preps
            )
            # stacked on the host (NumPy): `jnp.stack` would compile one small
            # program per field shape before the fit even starts
            rows = jtu.tree_map(
                lambda *x: np.stack(x),
                *[
                    jtu.tree_map(lambda *r: np.stack(r), *[r for _, r in p.rows])
                    for p in padded
                ],
            )
            cases = jtu.tree_map(lambda *x: np.stack(x), *[p.arrays for p in padded])
            fits = jax.device_get(fit_cases(rows, cases, MAIN_STEPS))
            fits = _continue_stopped(
                padded, rows, cases, fits, reuse_shape=len(items) <= chunk
            )
            for j, i in enumerate(part):
                fit = {
                    k: np.asarray(getattr(fits, k))[j]
                    for k in fits.__dataclass_fields__
                }
                att = attribute(preps[j], fit)
                out[i] = _result(preps[j], att, items[i][3])
                if on_result is not None:
                    on_result(i, out[i])
    return out


def diagnose_gap(
    plant: Hammerstein, dt: float, estimation: dict, validation: dict
) -> GapDiagnosis:
    """Diagnose the gap between `plant` (the nominal model) and two records.

    **Arguments:**

    - `plant`: nominal Hammerstein model (identity, piecewise-linear or tabulated
      map; discrete or continuous linear block of order <= 4).
    - `dt`: sampling period (s).
    - `estimation`, `validation`: `{"t", "v", "y"}` dicts of NumPy arrays, two
      separate experiments; effects are fitted on the first, scored on the second.

    **Returns:** a `GapDiagnosis` (the contract's fields and the figure data).
    """
    return diagnose_many([(plant, dt, estimation, validation)])[0]
