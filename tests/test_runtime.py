"""Process-wide runtime settings: the on-disk compilation cache, the ISA cap."""

import jax
from helpers import needs_isa_cap

from hamjax._runtime import use_compilation_cache


def test_compilation_cache_folder_and_opt_out(tmp_path, monkeypatch):
    before = jax.config.jax_compilation_cache_dir
    try:
        monkeypatch.setenv("HAMJAX_CACHE_DIR", "off")
        use_compilation_cache()
        assert jax.config.jax_compilation_cache_dir == before
        monkeypatch.setenv("HAMJAX_CACHE_DIR", str(tmp_path / "xla"))
        use_compilation_cache()
        assert jax.config.jax_compilation_cache_dir == str(tmp_path / "xla")
        assert (tmp_path / "xla").is_dir()
        monkeypatch.delenv("HAMJAX_CACHE_DIR")
        monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
        use_compilation_cache()
        assert (tmp_path / "xdg" / "hamjax" / "xla").is_dir()
    finally:
        jax.config.update("jax_compilation_cache_dir", before)


@needs_isa_cap
def test_every_lane_of_a_batched_filter_rounds_alike():
    """A row's result must not depend on where in a batch it runs (so a case's
    diagnosis on which other cases share its call): 16 direct-form filters of
    orders 1-3 padded to one length, as the diagnosis's fits run them, each
    bitwise the same at every position of the batch. With XLA's code for
    AVX-512 lanes 12-15 came out ~1e-14 off (`same_rounding_in_every_lane`,
    which conftest applies as the CLI does)."""
    import jax.numpy as jnp
    import numpy as np

    from hamjax._filters import filter_scan

    rng = np.random.default_rng(1)
    lanes, n = 16, 7
    b, a = np.zeros((lanes, n)), np.zeros((lanes, n))
    for i in range(lanes):
        order = 1 + i % 3
        a[i, : order + 1] = np.poly(rng.uniform(0.3, 0.95, order))
        b[i, 1 : order + 1] = 0.05 * rng.normal(size=order)
    u = rng.normal(size=(lanes, 4096))
    run = jax.jit(jax.vmap(lambda b, a, u: filter_scan(b, a, u, jnp.zeros(n - 1))[1]))
    y = np.asarray(run(b, a, u))
    for shift in range(1, lanes):
        at = np.roll(np.arange(lanes), shift)
        np.testing.assert_array_equal(np.asarray(run(b[at], a[at], u[at])), y[at])
    # and in batches of other widths (another device count splits them so)
    for width in (1, 3, 5, 8):
        for s in range(0, lanes, width):
            at = slice(s, s + width)
            np.testing.assert_array_equal(np.asarray(run(b[at], a[at], u[at])), y[at])


@needs_isa_cap
def test_a_nonlinear_recursion_rounds_alike_at_every_batch_width():
    """A recursion with a multiply-add around a `tanh` (as the friction loop's),
    vmapped over 160 lanes, each lane bitwise the same at batch widths 1-160.
    With fused multiply-adds (`XLA_FLAGS=--xla_cpu_max_isa=AVX2`) widths from 32 on
    gave 1e-14 other than widths up to 16: XLA fuses the operations by the batch's
    shape, and a fused `a * b + c` rounds once, an unfused one twice."""
    import jax.lax as lax
    import jax.numpy as jnp
    import numpy as np

    def step(c, x):
        c = 0.9 * c + jnp.tanh(x + 0.3 * c)
        return c, c

    run = jax.jit(jax.vmap(lambda x: lax.scan(step, jnp.zeros(()), x)[1]))
    x = 3.0 * np.random.default_rng(0).normal(size=(160, 256))
    one = np.concatenate([np.asarray(run(x[i : i + 1])) for i in range(160)])
    for width in (5, 16, 32, 80, 160):
        for s in range(0, 160, width):
            np.testing.assert_array_equal(
                np.asarray(run(x[s : s + width])), one[s : s + width]
            )


def test_the_studies_that_diagnose_ask_for_the_cap():
    from hamjax.cli.study import STUDY_PACKAGES
    from hamjax.montecarlo.registry import discover_studies

    studies = discover_studies(STUDY_PACKAGES)
    assert {n for n, s in studies.items() if s.diagnoses} == {
        "blind-benchmark",
        "real-data-gap",
    }
    assert not studies["simulation-throughput"].diagnoses


def test_the_isa_cap_leaves_a_user_choice_and_other_platforms(monkeypatch):
    from hamjax import _runtime

    monkeypatch.setenv("XLA_FLAGS", "--xla_cpu_max_isa=AVX2")
    _runtime.same_rounding_in_every_lane()
    assert _runtime.os.environ["XLA_FLAGS"] == "--xla_cpu_max_isa=AVX2"
    monkeypatch.setenv("XLA_FLAGS", "")
    monkeypatch.setattr(_runtime.platform, "machine", lambda: "aarch64")
    _runtime.same_rounding_in_every_lane()
    assert _runtime.os.environ["XLA_FLAGS"] == ""
    monkeypatch.setattr(_runtime.platform, "machine", lambda: "x86_64")
    _runtime.same_rounding_in_every_lane()
    assert _runtime.os.environ["XLA_FLAGS"] == "--xla_cpu_max_isa=AVX"
