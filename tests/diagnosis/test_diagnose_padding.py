"""`diagnose_many(padding=)`: two tiny cases, each diagnosed in a call of its own
padded as the whole run (and prepared on one thread, the whole run's on
several), have exactly the numbers of that whole run (with more
batch-mates the last digits may differ: `hamjax diagnose` splits a run into the
fixed blocks of `run_blocks`, tested here too)."""

import jax.random as jr
import numpy as np
import pytest

import hamjax.diagnosis.diagnose as diagnose_module
from hamjax.diagnosis.diagnose import (
    Padding,
    _fitted_n_params,
    diagnose_many,
    run_blocks,
    run_padding,
)
from hamjax.diagnosis.layout import n_free_parameters
from hamjax.models import Hammerstein, PiecewiseLinear
from hamjax.papers.gap.demo_cases import tiny_case


def _items():
    """Two tiny cases that pad differently alone: 600 samples and an identity
    map; 200 samples and the same plant written with a piecewise-linear map
    (identity-valued), whose rows are wider."""
    plant, dt, est, val = tiny_case(jr.key(0), "saturation", n=600, noise=1e-3)
    p2, _, est2, val2 = tiny_case(jr.key(1), "none", n=200, noise=1e-3)
    wide = Hammerstein(PiecewiseLinear(k1=1.0, k2=1.0), p2.linear)
    return [(plant, dt, est, val), (wide, dt, est2, val2)]


def _same(a, b) -> bool:
    """Every field equal, arrays bit for bit."""
    fields = a.__dataclass_fields__
    return all(
        np.array_equal(getattr(a, f), getattr(b, f))
        if isinstance(getattr(a, f), np.ndarray)
        else getattr(a, f) == getattr(b, f)
        for f in fields
    )


@pytest.mark.slow
def test_a_case_alone_with_the_runs_padding_has_the_runs_numbers(monkeypatch):
    items = _items()
    # the whole run prepares its cases on threads, each case alone on one: the
    # numbers do not depend on that either
    monkeypatch.setattr(diagnose_module, "host_cores", lambda: 4)
    whole = diagnose_many(items)
    monkeypatch.setattr(diagnose_module, "host_cores", lambda: 1)
    pad = run_padding(
        (p, max(e["v"].shape[0], v["v"].shape[0])) for p, _, e, v in items
    )
    # the two cases do pad differently: alone, each would get a smaller padding
    assert pad != run_padding([(items[0][0], 600)])  # narrower
    assert pad != run_padding([(items[1][0], 200)])  # shorter
    # (the first case alone with its own padding has other last digits: measured)
    for k in range(len(items)):
        (alone,) = diagnose_many([items[k]], padding=pad)
        assert _same(alone, whole[k]), k


def test_run_padding_takes_the_widest_and_longest():
    (plant, *_), (wide, *_) = _items()
    pad = run_padding([(plant, 600), (wide, 200), (plant, 20_000)])
    assert pad.n_params == n_free_parameters(wide) > n_free_parameters(plant)
    # records up to 8192 samples share one group, padded to its longest
    assert pad.lengths == ((8192, 1024), (32768, 32768))
    # a case without a nominal counts as the widest one fit_nominal returns
    assert run_padding([(None, 200)]).n_params == _fitted_n_params()
    # a call whose cases do not fit in the padding given is refused
    with pytest.raises(ValueError, match="do not fit"):
        diagnose_many(_items(), padding=Padding(pad.n_params, ((8192, 512),)))


@pytest.mark.parametrize("size", [1, 2, 3, 32])
def test_run_blocks_cut_the_run_into_consecutive_blocks(size, monkeypatch):
    monkeypatch.setattr(diagnose_module, "CASES_PER_CALL", size)
    for n in (0, 1, size - 1, size, size + 1, 3 * size, 3 * size + 2):
        blocks = run_blocks(n)
        # every position once, in order, in blocks of `size` but the last
        assert [k for b in blocks for k in b] == list(range(n))
        assert all(len(b) == size for b in blocks[:-1])
        assert all(0 < len(b) <= size for b in blocks)
        assert len(blocks) == -(-n // size)  # ceil(n / size)
        # a longer run keeps the full blocks of a shorter one
        assert run_blocks(n + size)[: n // size] == blocks[: n // size]
