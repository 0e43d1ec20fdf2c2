"""Run the candidate fits of many cases as a work queue through one compiled batch.

Every fit is a *row* of one case (`layout.prepare`). The rows go through three
stages, all of them batches of the same `[N]` rows (row `i` on its own case), so
one compilation per record length serves a whole call:

1. **Screening.** Every row gets `SCREEN_STEPS` Levenberg-Marquardt steps: enough
   to rank the starts and the classes.
2. **Finishing** (`finishing_items`), once all rows of a case are screened: the
   rows the decision rests on get up to `FINISH_STEPS` more (the prediction-error
   fits of `whitening_items` likewise, once they are known);
3. **Continuation**: every fit after screening runs in passes of at most
   `FIRST_PASS` steps a batch; one still moving after its pass is queued again
   with its remaining budget and its damping, and resumes exactly where it
   stopped (`fit.fit_batch`'s `resume`): a row's fit is the same whether its
   budget ran in one batch or in several, so it does not depend on how many
   cases share the call.

Most rows converge within a pass or two, and a batch costs as much as its
slowest row: queueing the slow ones together, instead of letting each batch run
all its rows to the longest budget in it (a re-fit of the whole linear block has
`NOMINAL_STEPS`), is what the split buys. On the 80 control loops of
`hamjax blind make --family loops --seed 1` (2 cores) the passes after the
continuation's first took the queue from 116 s to 82 s, every diagnosis the same.

After screening the items wait in one queue per *need*: whether their row needs
the input-memory scan (rate limit, backlash) and whether it needs the feedback
loop (friction, feedback nonlinearity). Each device's share of a batch decides
at run time whether to run them (`fit._fit_flat`), so a share of one need runs
at that need's cost and not at the cost of every need at once (`_compose`).
A batch of the later stages runs as soon as one need fills it, so cases complete
(and are reported) early; once screening is over, what is left runs in padded
batches, pass after pass. On family B seed 9 (240 cases, 2 cores, one call,
compiled programs from the cache; old and new alternating twice) the per-need
shares took `hamjax diagnose` from 146 and 142 s to 113 and 113 s, every name
the same.
"""

from collections import defaultdict, deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import NamedTuple

import equinox as eqx
import jax
import jax.tree_util as jtu
import numpy as np

from ..simulation.sharding import effective_chunk
from .attribute import (
    Candidate,
    lr_over_refit,
    noise_candidates,
    reference,
    refit_over_nominal,
    whitening_noise,
)
from .augmented import Row, uses_feedback, uses_memory, uses_table
from .fit import (
    LAMBDA0,
    SUCCESSFUL,
    RowFit,
    fit_padded,
    theta_std,
    validation_start,
)
from .layout import (
    PROFILE_POINTS,
    Prepared,
    best_row_per_class,
    finite_sse,
    frees_valve_start,
    refits_linear,
    starts_at_nominal_numerator,
    validation_sse,
)
from .noise_fit import noise_direction, noise_filter, predictor_errors
from .nominal_fit import NOMINAL_STEPS
from .residuals import noise_std_differences


REFIT = "parameter_mismatch"
# Levenberg-Marquardt budget. Every row gets SCREEN_STEPS; the rows the decision
# rests on get FINISH_STEPS more. On the seed-100 exact benchmark, 30 + 120 steps
# and 8 + 40 steps named the same effects in 240 of 240 cases, at 231 s and 117 s.
SCREEN_STEPS = 8
FINISH_STEPS = 40
FIRST_PASS = 12  # steps of a pass: what a fit after screening gets per batch
CONTINUE_CLASSES = 4
# Cases whose screening rows fill one batch. A batch costs as much as its slowest
# row, so smaller batches waste less on padding: on the registered realistic set,
# 2-4 cases ran in 59-72 s, 8 in 82 s, 16 in 91 s (same effects named in all).
CASES_PER_BATCH = 4
# A call's last batches hold few rows (the passes of the last cases' fits, one
# after another), yet a padded batch costs about its width in rows (12 steps of
# prediction-error fits at 4096 samples, 2 cores: 4.0 s at 144 rows, 1.5 s at 48,
# whatever the rows in it): they run at a third of the width (one more compiled
# shape) in a call of at least TAIL_BATCHES screening batches, where that shape
# pays for its compilation. Seed-1 control loops: the prediction-error fits 45 ->
# 37 s, every name the same.
TAIL_FRACTION = 3
TAIL_BATCHES = 4
FIELDS = tuple(RowFit.__dataclass_fields__)


class NoiseSpec(NamedTuple):
    """A prediction-error fit's noise filter (`noise_fit.noise_filter`), its
    direction in the predictor's parameter (`noise_fit.noise_direction`; zero
    for a fixed filter), the prior weight, and how far the parameter has moved
    already (a resumed joint fit starts from its filter moved so far)."""

    fir: np.ndarray
    ar: float
    weight: float
    dfir: np.ndarray
    dar: float
    shift: float = 0.0

    def moved(self, eta: float) -> "NoiseSpec":
        """The filter with its parameter moved by `eta` more."""
        return self._replace(
            fir=self.fir + eta * self.dfir,
            ar=self.ar + eta * self.dar,
            shift=self.shift + eta,
        )


@dataclass
class Item:
    """One fit to run: row `row` of case `case`, from `theta0`, for `budget` steps."""

    case: int
    row: int
    theta0: np.ndarray
    lam0: float
    budget: int  # steps, the re-evaluation of `theta0` of a resumed item included
    stage: str  # "screen", "finish", "more" or "whiten"
    replace: str  # when the result replaces the row's: "always", "lower", "stopped"
    # a prediction-error fit's noise filter and prior weight (`whitening_items`)
    noise: NoiseSpec | None = None
    resume: bool = False  # continues a stopped fit exactly (`fit.fit_batch`)


def leading_rows(prep: Prepared, fits: dict) -> tuple:
    """`(sse, sse_val, refit, best, lead)`: each row's estimation and validation
    SSE, the re-fit's best row, the other classes' best rows (`{class: row}`)
    and the rows of the `CONTINUE_CLASSES` leading ones by estimation SSE."""
    sse, sse_val = finite_sse(fits), validation_sse(prep, fits)
    best = best_row_per_class(prep, sse, sse_val)
    refit = best.pop(REFIT)
    lead = sorted(best.values(), key=lambda k: sse[k])[:CONTINUE_CLASSES]
    return sse, sse_val, refit, best, lead


def finishing_items(c: int, prep: Prepared, fits: dict) -> list[Item]:
    """The rows of case `c` the decision rests on, after screening (`fits`: the
    `RowFit` fields of its rows, NumPy).

    - The re-fit row (`parameter_mismatch`), continued if it stopped at the step
      limit: it is the reference every structural candidate is tested against,
      so an unfinished one lets a structural row look significant.
    - The re-fit row again, restarted from the nominal parameters of the best
      structural row. The re-fit is nested in every structural candidate (each
      is neutral at its neutral parameters), so a structural row that ends far
      below it often marks a local minimum of the re-fit from the nominal start
      rather than an effect; the restart finds the re-fit's better minimum
      (kept only if its estimation SSE is lower).
    - The re-fit row restarted likewise from the nominal parameters of the
      structural row that the decision will test against it (the class of
      least validation error, `attribute`), where that is another row and the
      nested likelihood-ratio test finds it significant over the re-fit
      (`attribute.lr_over_refit`): the test assumes the re-fit at its optimum.
      The leading row by estimation SSE need not be that row: exact seed 100,
      case 102 (a 22 % parameter mismatch of a third-order plant) led with
      `extra_pole`, from whose start the re-fit stays at an SSE of 8.6; from
      the `backlash` row's, which validation chose, it reaches 1.07, below the
      backlash row's own 1.11, and the case was named `backlash`.
    - The leading structural row restarted the other way round: its effect
      parameters as screened, its nominal part back at the nominal values. While
      the effect's parameters are still far off, the nominal part drifts to
      compensate and can stay in a valley once the effect is in place (an output
      clip found exactly, the map's levels left 25-40 % off); the nominal
      model is the better start for them (kept only if its SSE is lower).
    - The best rows of the `CONTINUE_CLASSES` leading structural classes (by
      estimation SSE), continued if they stopped: an unfinished row of the true
      effect lets another effect win. Classes further down were measured not to
      change the decision on the development benchmark, and continuing every
      class doubled the cost.
    - A row that re-fits the whole linear block (`layout.refits_linear`, only
      beside hamjax's own nominal), continued to the budget of the nominal fit,
      which fits the same block (`nominal_fit.NOMINAL_STEPS`), whatever its
      class's rank: it starts at the linear fit's numerator, far from its own
      optimum, so a few screening steps cannot rank it. Not a row that starts at
      a fitted numerator (`layout.starts_at_nominal_numerator`: the stick-slip
      profile's), which is ranked and continued as any other.
    """
    leading = leading_rows(prep, fits)
    sse, _, i_pm, best, lead = leading
    used = np.asarray(prep.rows[i_pm][1].idx) < prep.arrays.anchor.shape[0]
    far = lambda r: refits_linear(r) and starts_at_nominal_numerator(r)  # noqa: E731
    budget = lambda k: (  # noqa: E731
        NOMINAL_STEPS - SCREEN_STEPS if far(prep.rows[k][1]) else FINISH_STEPS
    )
    linear = [k for k, (_, r) in enumerate(prep.rows) if far(r)]
    out = [
        Item(c, k, fits["theta"][k], LAMBDA0, budget(k), "finish", "stopped")
        for k in dict.fromkeys([i_pm, *lead, *linear])
        if fits["result"][k] != SUCCESSFUL
    ]
    judged = judged_row(prep, fits, leading=leading)
    for k in dict.fromkeys(k for k in (lead[0], judged) if k is not None):
        start = np.where(used, fits["theta"][k], 0.0)  # its nominal part only
        out.append(Item(c, i_pm, start, LAMBDA0, FINISH_STEPS, "finish", "lower"))
    back = np.where(used, 0.0, fits["theta"][lead[0]])  # effect part only
    out.append(Item(c, lead[0], back, LAMBDA0, FINISH_STEPS, "finish", "lower"))
    return out


def judged_row(
    prep: Prepared, fits: dict, *, leading: tuple | None = None
) -> int | None:
    """The structural row of least validation SSE (the class `attribute` tests
    against the re-fit) where the nested likelihood-ratio test finds it
    significant over the re-fit (`attribute.lr_over_refit`, at the threshold of
    the case's structural classes); None otherwise. `leading`: `leading_rows`
    of these fits, where the caller has it."""
    sse, sse_val, i_pm, best, _ = leading or leading_rows(prep, fits)
    if not best:
        return None
    k = min(best.values(), key=lambda k: sse_val[k])
    lr, threshold, beyond = lr_over_refit(prep, sse, i_pm, k, len(best))
    if beyond > 0 and np.isfinite(lr) and lr > threshold:
        return k
    return None


def _direction(noise_c: Candidate) -> tuple[np.ndarray, float]:
    """The filter's direction in the predictor's parameter (the noise candidate
    `noise_c`'s, `attribute.noise_candidates`), which the prediction-error fits
    free with the row's (`fit.normal_equations`); zero (the filter fixed) where
    the filter only stands in for the predictor that `attribute` judges through
    (the flicker model's: `Candidate.whitening` is not its `predictor`)."""
    if noise_c.whitening != noise_c.predictor:
        return np.zeros(3), 0.0
    return noise_direction(noise_c.predictor[0])


def whitening_items(c: int, prep: Prepared, fits: dict) -> list[Item]:
    """The prediction-error fits of case `c`, once its rows are finished: when the
    reference's residual (the nominal's, or the re-fit's beside a fitted nominal:
    `attribute.reference`) has a significant noise model ($A(q)$,
    `attribute.whitening_noise` of `fits["noise"]`), the best rows of the
    re-fit, of the
    `CONTINUE_CLASSES` leading structural classes (by estimation SSE, as in
    `finishing_items`) and of the class of least validation error again, each
    from its output-error fit, minimising the one-step-ahead errors $A(q) r$ with
    the predictor's parameter fitted too, from the reference's value (Box-Jenkins:
    `fit.normal_equations`, `NoiseSpec`; fixed where $A$ stands in for the
    flicker predictor); `attribute` judges the
    deterministic gap through $A$ on these fits (the other classes' on their
    output-error fits). The prior weight, a noise
    variance times the prior's precision (`layout.prior_weight`), is scaled by
    the ratio of the innovations' variance to the white output noise's (both by
    `residuals.noise_std_differences`, on the reference's estimation residual:
    the nominal's, or the re-fit's beside a fitted nominal).
    None of them when the noise model is not significant."""
    _, r_est, r_val = reference(prep, fits)
    noise_c = whitening_noise(fits["noise"], r_val)
    if noise_c is None:
        return []
    predictor = noise_c.whitening
    e_est = predictor_errors(*predictor, r_est)
    sigma, sigma_e = noise_std_differences(r_est), noise_std_differences(e_est)
    ratio = (sigma_e / sigma) ** 2 if sigma > 0 else 1.0
    weight = float(prep.arrays.prior_weight) * ratio
    direction = _direction(noise_c)
    noise = NoiseSpec(*noise_filter(*predictor), weight, *direction)
    sse, sse_val, refit, best, lead = leading_rows(prep, fits)
    chosen = min(best.values(), key=lambda k: sse_val[k])
    return [
        Item(c, k, fits["theta"][k], LAMBDA0, FINISH_STEPS, "whiten", "always", noise)
        for k in dict.fromkeys([refit, *lead, chosen])
        if np.isfinite(sse[k])
    ]


def merge(fits: dict, item: Item, new: dict) -> None:
    """Write a finished item's fit into its case's rows when the rule allows: a
    screening fit always; after it, the lowest estimation SSE of the row's fits
    (a continuation also at a tie, a restart only if strictly lower). A row's
    finishing items may finish in either order (in one batch or in several, by
    the cases sharing the call), and the row ends the same."""
    k = item.row
    if item.stage == "whiten":  # the prediction-error fits, beside the rows
        fits = fits["whitened"]
    if item.replace == "always":
        take = True
    elif item.replace == "lower":  # a restart: kept only if strictly better
        take = new["sse_est"] < fits["sse_est"][k]
    else:  # a continuation: kept if it did not get worse
        take = new["sse_est"] <= fits["sse_est"][k]
    if take:
        for name in FIELDS:
            fits[name][k] = new[name]


def validation_starts(prep: Prepared, fits: dict, rows=None) -> None:
    """The validation output of each row that fits the valve's start
    (`layout.frees_valve_start`), among `rows` (None: all), simulated from the
    validation record's own start (`fit.validation_start`), in place: once the
    case's rows are finished (screening judges them started at $v_0$), and once
    their prediction-error fits are."""
    ks = range(len(prep.rows)) if rows is None else rows
    ks = [k for k in ks if frees_valve_start(prep.rows[k][1])]
    if ks:
        fits["y_val"][ks] = validation_start(
            fits["params"][ks],
            [prep.rows[k][1] for k in ks],
            prep.arrays,
            batch=PROFILE_POINTS,  # the rows that free the start: one program
        )


def parameter_std(prep: Prepared, fits: dict) -> np.ndarray:
    """Gauss-Newton standard errors of every row's `theta` (`[row, P]`)."""
    n_slots = prep.arrays.anchor.shape[0]
    return np.stack(
        [
            theta_std(fits["jtj"][k], fits["s2"][k], np.asarray(r.idx) < n_slots)
            for k, (_, r) in enumerate(prep.rows)
        ]
    )


def batch_size(preps: list[Prepared], cases_per_batch: int = CASES_PER_BATCH) -> int:
    """Rows per batch: the screening rows of `cases_per_batch` cases (fewer when
    the call has fewer cases), a multiple of the device count."""
    rows = max(len(p.rows) for p in preps)
    return effective_chunk(
        rows * min(cases_per_batch, len(preps)), jax.local_device_count()
    )


def run_queue(
    preps: list[Prepared],
    batch: int,
    on_case: Callable[[int, dict], None],
    while_compiling: Callable[[], None] | None = None,
) -> None:
    """Fit every row of every case (all with the same padded record length) and call
    `on_case(c, fits)` as soon as case `c` is finished, `fits` being its rows'
    `RowFit` fields (NumPy, leading axis row) plus `theta_std`. `while_compiling`:
    as in `fit.fit_batch`. Batches are `batch` rows wide; in a call of at least
    `TAIL_BATCHES` screening batches, one of at most a `TAIL_FRACTION` of that
    many rows is padded to that narrower width only. After screening each
    device's share of a batch holds rows of one need (`_compose`)."""
    screen: deque = deque()
    # after screening, one queue per need (`need`): finishing rows, their
    # continuations and prediction-error fits alike
    later: dict[tuple, deque] = defaultdict(deque)
    fits: list[dict | None] = [None] * len(preps)
    outstanding = [len(p.rows) for p in preps]
    arrays = jtu.tree_map(lambda *x: np.stack(x), *[p.arrays for p in preps])
    rows = [
        jtu.tree_map(lambda *x: np.stack(x), *[r for _, r in p.rows]) for p in preps
    ]  # per case, its rows stacked
    # The rows that need the input-memory scan (rate limit, backlash) first, together,
    # and those that need the feedback loop (friction, feedback nonlinearity) last,
    # together: the batches (per device) left without any skip that scan, or that
    # loop (`fit._fit_flat`).
    memory = [
        np.asarray(uses_memory(r.free, p.nominal.nl_kind))
        for r, p in zip(rows, preps, strict=True)
    ]
    feedback = [np.asarray(uses_feedback(r.free)) for r in rows]
    order = sorted(  # stable: otherwise in case order
        ((c, k) for c, m in enumerate(memory) for k in range(m.shape[0])),
        key=lambda ck: (not memory[ck[0]][ck[1]], bool(feedback[ck[0]][ck[1]])),
    )
    screen.extend(
        Item(c, k, rows[c].theta0[k], LAMBDA0, SCREEN_STEPS, "screen", "always")
        for c, k in order
    )

    def need(item: Item) -> tuple[bool, bool]:
        # what the item's batch must run (`fit._fit_flat`): the input-memory
        # scan, the feedback loop
        return bool(memory[item.case][item.row]), bool(feedback[item.case][item.row])

    def queue(items: Iterable[Item]) -> None:
        for it in items:
            later[need(it)].append(it)

    # What every batch of the call needs, where that is known in advance (a
    # smaller compiled program); None: decided per batch at run time. A call of
    # one screening batch gains nothing from skipping the memory scan or the
    # feedback loop at run time.
    tabulated = {bool(uses_table(p.nominal.nl_kind)) for p in preps}
    one = len(order) <= batch
    tail = batch
    if len(order) >= TAIL_BATCHES * batch:
        tail = effective_chunk(-(-batch // TAIL_FRACTION), jax.local_device_count())
    flags = {
        "memory": True if one else None,
        "table": tabulated.pop() if len(tabulated) == 1 else None,
        "feedback": bool(any(f.any() for f in feedback)) if one else None,
    }

    def done(item: Item, new: dict, given: int) -> None:
        c = item.case
        if fits[c] is None:
            R = len(preps[c].rows)
            fits[c] = {
                name: np.zeros((R, *np.shape(x)), np.asarray(x).dtype)
                for name, x in new.items()
            }
        if item.noise is not None:  # the parameter's move since the first filter
            new["noise_shift"] = new["noise_shift"] + item.noise.shift
        merge(fits[c], item, new)
        spent = int(new["steps"])
        if (
            item.stage != "screen"
            and new["result"] != SUCCESSFUL
            and spent < item.budget
            and (item.stage == "finish" or spent >= given)  # stopped by its pass
        ):
            stage = "whiten" if item.stage == "whiten" else "more"
            queue(
                [
                    Item(  # resumes with its pending step (one more to re-evaluate)
                        c,
                        item.row,
                        new["theta"],
                        float(new["lam"]),
                        item.budget - spent + 1,
                        stage,
                        item.replace,
                        None
                        if item.noise is None
                        else item.noise.moved(
                            float(new["noise_shift"]) - item.noise.shift
                        ),
                        resume=True,
                    )
                ]
            )
            return
        outstanding[c] -= 1
        if item.stage == "screen" and outstanding[c] == 0:
            extra = finishing_items(c, preps[c], fits[c])
            queue(extra)
            outstanding[c] = len(extra)
        elif item.stage in ("finish", "more") and outstanding[c] == 0:
            validation_starts(preps[c], fits[c])
            fits[c]["theta_std"] = parameter_std(preps[c], fits[c])
            if preps[c].fitted:  # the reference, once (`attribute` reads it too)
                fits[c]["reference"] = refit_over_nominal(preps[c], fits[c])
            fits[c]["noise"] = noise_candidates(preps[c], fits[c])  # `attribute` too
            extra = whitening_items(c, preps[c], fits[c])
            if extra:
                fits[c]["whitened"] = {k: np.copy(fits[c][k]) for k in FIELDS}
                # the rows fitted by prediction error (the others keep their
                # output-error fits: `attribute` tests only these by likelihood)
                fits[c]["whitened"]["rows"] = sorted({it.row for it in extra})
            queue(extra)
            outstanding[c] = len(extra)
        if outstanding[c] == 0:
            if "whitened" in fits[c]:
                w = fits[c]["whitened"]
                validation_starts(preps[c], w, w["rows"])
                w["theta_std"] = parameter_std(preps[c], w)
            on_case(c, fits[c])

    n_dev = jax.local_device_count()
    while screen or any(later.values()):
        if screen and _most_whole_shares(later, batch // n_dev) < n_dev:
            take = [screen.popleft() for _ in range(min(batch, len(screen)))]
            budgets = [it.budget for it in take]
            real = [True] * len(take)
            width = tail if len(take) <= tail else batch
        else:  # after screening: each device's share of one need
            # narrower only at the end, where what is left fits in its shares
            narrow = _shares_needed(later, tail // n_dev) <= n_dev
            width = tail if narrow else batch
            take, real = _compose(later, width // n_dev, n_dev)
            budgets = [
                min(it.budget, FIRST_PASS) if r else 0
                for it, r in zip(take, real, strict=True)
            ]
        out = run_batch(take, budgets, rows, arrays, width, while_compiling, flags)
        for j, it in enumerate(take):
            if real[j]:
                done(it, {name: x[j] for name, x in out.items()}, budgets[j])


def _most_whole_shares(later: dict[tuple, deque], share: int) -> int:
    """The most device shares of `share` items that one need's queue fills."""
    return max((len(q) // share for q in later.values()), default=0)


def _shares_needed(later: dict[tuple, deque], share: int) -> int:
    """How many device shares of at most `share` items, each of one need, take
    every queued item."""
    return sum(-(-len(q) // share) for q in later.values())


def _compose(
    later: dict[tuple, deque], share: int, n_dev: int
) -> tuple[list[Item], list[bool]]:
    """A batch of `n_dev` device shares of `share` items taken from `later`
    (queues by need), each share of one need: whole shares first, of a need
    that fills the batch alone, else of the costlier needs (the memory scan,
    the feedback loop) before the plain one, the fuller first; then part-filled
    shares. A share's free lanes take rows of a need it runs anyway (one that
    needs nothing more: plain rows in any share). Returns `(items, real)`: a
    share padded with copies of its first item and missing shares with copies
    of the batch's first (`real` False: at a zero budget, fitted for nothing).

    `fit._fit_flat` decides per share whether to run the input-memory scan and
    the feedback loop, so a share of rows that need neither runs at the cost of
    the plain filter (on the 80 first cases of family B seed 9, 2 cores: 12
    steps of 66 rows 0.5 s, against 2.2 s with rows of every need mixed)."""
    keys = sorted(
        later,
        key=lambda k: (len(later[k]) // share < n_dev, not any(k), -len(later[k]), k),
    )
    parts = []  # (need, items)
    for whole in (True, False):
        for key in keys:
            q = later[key]
            while q and len(parts) < n_dev and (len(q) >= share or not whole):
                parts.append((key, [q.popleft() for _ in range(min(share, len(q)))]))
    # lanes left in a share carry rows of a need it runs anyway (no more than its)
    for key, part in parts:
        for other in keys:
            q = later[other]
            rides = all(o <= k for o, k in zip(other, key, strict=True))
            while rides and q and len(part) < share:
                part.append(q.popleft())
    items, real = [], []
    for _, part in parts + [((), [])] * (n_dev - len(parts)):
        pad = part[0] if part else parts[0][1][0]
        items += part + [pad] * (share - len(part))
        real += [True] * len(part) + [False] * (share - len(part))
    return items, real


def run_batch(
    take: list[Item],
    budgets: list[int],
    rows: list[Row],
    arrays,
    batch: int,
    while_compiling: Callable[[], None] | None = None,
    flags: dict | None = None,
) -> dict:
    """One batch: the items' rows and cases gathered on the host and fitted in
    a batch of `batch` (`fit.fit_padded`: padded with copies of the first item
    at a zero budget). `while_compiling`, `flags` (`memory`, `table`,
    `feedback`): as in `fit.fit_batch`."""
    pick = lambda name: np.stack(  # noqa: E731
        [np.asarray(getattr(rows[it.case], name))[it.row] for it in take]
    )
    row = Row(
        idx=pick("idx"),
        theta0=np.stack([it.theta0 for it in take]),
        tau=pick("tau"),
        free=pick("free"),
        held=pick("held"),
    )
    cases = jtu.tree_map(lambda x: x[np.asarray([it.case for it in take])], arrays)
    noisy = [(j, it.noise) for j, it in enumerate(take) if it.noise is not None]
    if noisy:  # the prediction-error fits' noise filters and prior weights
        names = ("noise_fir", "noise_ar", "prior_weight", "noise_dfir", "noise_dar")
        columns = [np.copy(getattr(cases, name)) for name in names]
        for j, spec in noisy:
            for x, value in zip(columns, spec[:5], strict=True):
                x[j] = value
        cases = eqx.tree_at(
            lambda a: tuple(getattr(a, name) for name in names), cases, tuple(columns)
        )
    fit = fit_padded(
        row,
        cases,
        np.asarray(budgets, dtype=np.int32),
        np.asarray([it.lam0 for it in take]),
        batch,
        while_compiling,
        resume=np.asarray([it.resume for it in take]),
        **(flags or {}),
    )
    return host_fields(fit)


def host_fields(fit: RowFit) -> dict[str, np.ndarray]:
    """The fields of fitted rows as NumPy; `result` (a `RESULTS` item) as its
    integer codes, `SUCCESSFUL` for a converged row."""
    fields = {name: getattr(fit, name) for name in FIELDS}
    fields["result"] = fields["result"]._value
    return {name: np.asarray(x) for name, x in fields.items()}
