"""argparse types shared by the commands and by the studies' own options."""

import argparse
import math


def _list_of(text: str, parse, what: str) -> list:
    try:
        values = [parse(x) for x in text.split(",") if x.strip() != ""]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated {what}s, got {text!r}"
        ) from None
    if not values:
        raise argparse.ArgumentTypeError(f"expected at least one {what}")
    return values


def float_list(text: str) -> list[float]:
    """Parse a comma-separated list of finite numbers (`--levels=-6,-3,3,6`)."""
    values = _list_of(text, float, "number")
    if not all(math.isfinite(x) for x in values):
        raise argparse.ArgumentTypeError(f"numbers must be finite, got {text!r}")
    return values


def _parsed(text: str, parse, what: str):
    try:
        return parse(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None


def positive_float(text: str) -> float:
    """A finite number > 0."""
    x = _parsed(text, float, "a number")
    if not (math.isfinite(x) and x > 0):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return x


def positive_int(text: str) -> int:
    """An integer >= 1."""
    x = _parsed(text, int, "an integer")
    if x < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {text!r}")
    return x


def int_list(text: str) -> list[int]:
    """Parse a comma-separated list of integers (`--orders=1,2,3`)."""
    return _list_of(text, int, "integer")


def word_list(text: str) -> list[str]:
    """Parse a comma-separated list of words (`--modes=exact,realistic`)."""
    values = [x.strip() for x in text.split(",") if x.strip() != ""]
    if not values:
        raise argparse.ArgumentTypeError("expected at least one word")
    return values
