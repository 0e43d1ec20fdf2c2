"""Process-wide runtime settings applied at the entry points (CLI, tests)."""

import os
import platform


_EIGEN_FLAG = "--xla_cpu_multi_thread_eigen=false"


def avoid_eigen_pool_hang() -> None:
    """Run XLA's CPU Eigen kernels single-threaded unless the user chose otherwise.

    With jax 0.10 on CPU, vmapped graphs holding LAPACK calls (batched `eigh`)
    were seen to wedge XLA's Eigen thread pool, with every thread asleep; the same
    has been reported elsewhere for vmap graphs. Single-threaded Eigen avoids it at
    a cost of about 15% on the heaviest paths; XLA still runs independent ops in
    parallel. Must run before the first computation (XLA reads the flags when the
    backend starts); set `XLA_FLAGS=--xla_cpu_multi_thread_eigen=true` to opt out.
    """
    _add_xla_flag(_EIGEN_FLAG)


_ISA_FLAG = "--xla_cpu_max_isa=AVX"


def same_rounding_in_every_lane() -> None:
    """Cap XLA's CPU code at AVX (no fused multiply-add) on x86-64 unless the user
    chose an ISA.

    A row's fit must not depend on the rows beside it (which other cases share
    the call), nor on how many lanes a device runs (the device count). Two
    things made it so, both seen to change a control loop's name:
    - on a CPU with AVX-512, XLA's code for a `vmap`ped scan rounded lanes 12-15
      of a 16-lane batch ~1e-15 off what the same lane gave elsewhere (a loop
      named `backlash` among the benchmark's 40 sticky loops, `coloured_noise`
      alone or among all 80);
    - with FMA, whether `a * b + c` rounds once or twice depends on how XLA fuses
      the operations, which depends on the batch's width: a recursion with a
      `tanh` in it came out 1e-14 apart at widths up to 16 and from 32 on (11
      of seed 3's 40 sticky loops not bitwise the same on one device and on two,
      at AVX2).
    Without FMA every operation rounds once wherever XLA puts it; with the
    reductions in a fixed order (`_linalg.fixed_order_sum`) and one program per
    device (`diagnosis.fit._run_on_devices`) the 40 loops are bitwise the same on
    one device and on two (the pieces are tested in `tests/test_runtime.py`,
    `tests/test_linalg.py` and the two-device fit test). The cap costs little:
    240 family-B cases in one call 100.9 and 97.6 s at AVX2 against 104.5 and
    100.4 s at AVX (2 cores, cache off, alternating). Applied where
    cases are diagnosed (`hamjax diagnose`, `demo` and the studies that
    diagnose), not to the Monte Carlo simulations, which a cap slowed by about a
    fifth (`benchmark_throughput.py --quick`) and whose results are continuous.
    Must run before the first computation, as `avoid_eigen_pool_hang`; set
    `XLA_FLAGS=--xla_cpu_max_isa=...` to choose otherwise. Other platforms: a
    no-op (there a fit may round differently at another batch width).
    """
    if has_isa_cap():
        _add_xla_flag(_ISA_FLAG)


def has_isa_cap() -> bool:
    """Whether this CPU is one `same_rounding_in_every_lane` caps (x86-64)."""
    return platform.machine().lower() in ("x86_64", "amd64")


def _add_xla_flag(flag: str) -> None:
    """Append `--name=value` to `XLA_FLAGS` unless the user already set `--name`."""
    flags = os.environ.get("XLA_FLAGS", "")
    if flag.split("=")[0] not in flags:
        os.environ["XLA_FLAGS"] = f"{flags} {flag}".strip()


_DEVICES_FLAG = "--xla_force_host_platform_device_count"


def host_cores() -> int:
    """The CPU cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def split_cpu_into_devices() -> None:
    """Expose each CPU core as a JAX device, so work sharded over devices (the
    diagnosis's batched fits) runs on every core.

    Only when the user has not set the device count and JAX's backend has not
    started yet (XLA reads the flag once); otherwise a no-op. Code paths that do
    not shard keep running on device 0, as before.
    """
    import jax._src.xla_bridge as xb

    if xb.backends_are_initialized():
        return
    cores = host_cores()
    if cores > 1:
        _add_xla_flag(f"{_DEVICES_FLAG}={cores}")


def use_compilation_cache() -> None:
    """Keep XLA's compiled programs on disk between `hamjax` runs.

    The diagnosis compiles its batched fits for 3-5 s (once per call for records
    up to 8192 samples); with the cache a later call with the same shapes skips
    that. The folder is
    `$HAMJAX_CACHE_DIR`, else `$XDG_CACHE_HOME/hamjax/xla` (default
    `~/.cache/hamjax/xla`); `HAMJAX_CACHE_DIR=off` disables it. Only programs that
    took over a second to compile are stored. Results do not depend on it.
    """
    import jax

    where = os.environ.get("HAMJAX_CACHE_DIR")
    if where is not None and where.strip().lower() in ("", "0", "off", "none"):
        return
    if where is None:
        base = os.environ.get("XDG_CACHE_HOME") or os.path.join(
            os.path.expanduser("~"), ".cache"
        )
        where = os.path.join(base, "hamjax", "xla")
    try:
        os.makedirs(where, exist_ok=True)
    except OSError:
        return  # a read-only home: run without the cache
    jax.config.update("jax_compilation_cache_dir", where)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
