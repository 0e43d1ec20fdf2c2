"""The Hammerstein plant $v \\to F \\to u \\to G \\to w$."""

import equinox as eqx

from .._checks import concrete
from .linear import AbstractLinearBlock
from .nonlinearities import (
    AbstractHysteresisNonlinearity,
    AbstractNonlinearity,
    AbstractStaticNonlinearity,
    Backlash,
)
from .nonlinearities.output_scaled import OutputScaled
from .nonlinearities.scaled import Scaled


class Hammerstein(eqx.Module):
    """A nonlinearity followed by a linear block (the composition, no logic)."""

    nonlinearity: AbstractNonlinearity
    linear: AbstractLinearBlock

    def __check_init__(self):
        if not isinstance(self.nonlinearity, AbstractNonlinearity):
            raise TypeError(
                "Hammerstein.nonlinearity must be a hamjax nonlinearity; got "
                f"{type(self.nonlinearity).__name__}"
            )
        if not isinstance(self.linear, AbstractLinearBlock):
            raise TypeError(
                "Hammerstein.linear must be a hamjax linear block; got "
                f"{type(self.linear).__name__}"
            )


def scale_nonlinearity(
    nonlinearity: AbstractNonlinearity, gain
) -> AbstractNonlinearity:
    """$k F$: the nonlinearity with its output multiplied by `gain`."""
    value = concrete(gain)
    if isinstance(nonlinearity, Backlash) and value is not None and value > 0:
        # A positive gain keeps it a Backlash (tabulatable, borders in output units).
        u0 = None if nonlinearity.u0 is None else nonlinearity.u0 * gain
        return Backlash(
            ascending=Scaled(inner=nonlinearity.ascending, gain=gain),
            descending=Scaled(inner=nonlinearity.descending, gain=gain),
            u0=u0,
        )
    if isinstance(nonlinearity, AbstractHysteresisNonlinearity):
        return OutputScaled(inner=nonlinearity, gain=gain)
    if isinstance(nonlinearity, AbstractStaticNonlinearity):
        return Scaled(inner=nonlinearity, gain=gain)
    raise TypeError(f"cannot scale a {type(nonlinearity).__name__}")


def fold_output_scale(plant: Hammerstein) -> Hammerstein:
    """A hysteresis operator with its output scaled by $k$ (`OutputScaled`, seed
    000's $kF$ for $G(0) < 0$) as the unscaled operator before $kG$: the same
    plant from input to output (the form `model.json` writes and the diagnosis
    re-fits)."""
    nl = plant.nonlinearity
    if isinstance(nl, OutputScaled):
        return Hammerstein(nl.inner, plant.linear.scaled(nl.gain))
    return plant


def normalise_static_gain(plant: Hammerstein) -> Hammerstein:
    """The seed-000 normalisation $(kF, G/k)$ with $k = G(0)$, so that $G(0) = 1$.

    The input-output behaviour is unchanged. Raises `ValueError` if $G(0) = 0$.
    """
    k = plant.linear.static_gain()
    value = concrete(k)
    if value is not None and value == 0.0:
        raise ValueError("cannot normalise: the linear block's static gain G(0) is 0")
    return Hammerstein(
        scale_nonlinearity(plant.nonlinearity, k), plant.linear.scaled(1 / k)
    )
