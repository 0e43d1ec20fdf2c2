"""Progress bar for long runs: realisations done, realisations/s, time left."""

import sys

from tqdm import tqdm


def progress_bar(
    *, total: int, initial: int, name: str, quiet: bool, unit: str = "real"
) -> tqdm:
    """A `tqdm` bar on stderr; silent if `quiet` or stderr is not a terminal."""
    disable = quiet or not _stderr_is_tty()
    return tqdm(
        total=total,
        initial=initial,
        desc=name or "monte carlo",
        unit=unit,
        unit_scale=True,
        dynamic_ncols=True,
        disable=disable,
        file=sys.stderr,
    )


def _stderr_is_tty() -> bool:
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False
