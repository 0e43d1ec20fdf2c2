"""The plant models: linear blocks, nonlinearities, noise and the Hammerstein plant."""

from types import ModuleType as _ModuleType

from .hammerstein import (
    Hammerstein as Hammerstein,
    normalise_static_gain as normalise_static_gain,
    scale_nonlinearity as scale_nonlinearity,
)
from .linear import (
    AbstractContinuousLinearBlock as AbstractContinuousLinearBlock,
    AbstractDiscreteLinearBlock as AbstractDiscreteLinearBlock,
    AbstractLinearBlock as AbstractLinearBlock,
    ContinuousTransferFunction as ContinuousTransferFunction,
    DiscreteStateSpace as DiscreteStateSpace,
    DiscreteTransferFunction as DiscreteTransferFunction,
)
from .noise import (
    AbstractNoise as AbstractNoise,
    AR1Noise as AR1Noise,
    WhiteNoise as WhiteNoise,
    add_noise as add_noise,
    noise_std_for_snr as noise_std_for_snr,
)
from .nonlinearities import (
    AbstractHysteresisNonlinearity as AbstractHysteresisNonlinearity,
    AbstractNonlinearity as AbstractNonlinearity,
    AbstractStaticNonlinearity as AbstractStaticNonlinearity,
    Backlash as Backlash,
    BacklashState as BacklashState,
    DeadZone as DeadZone,
    Identity as Identity,
    OutputScaled as OutputScaled,
    PiecewiseLinear as PiecewiseLinear,
    Saturation as Saturation,
    Scaled as Scaled,
    Shifted as Shifted,
    Tabulated as Tabulated,
    apply_nonlinearity as apply_nonlinearity,
)


# Every model name above: `hamjax/__init__.py` re-exports this list (one list).
__all__ = sorted(
    name
    for name, value in globals().items()
    if not name.startswith("_") and not isinstance(value, _ModuleType)
)
