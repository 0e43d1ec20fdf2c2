from ._base import (
    AbstractHysteresisNonlinearity as AbstractHysteresisNonlinearity,
    AbstractNonlinearity as AbstractNonlinearity,
    AbstractStaticNonlinearity as AbstractStaticNonlinearity,
    apply_nonlinearity as apply_nonlinearity,
)
from .backlash import Backlash as Backlash, BacklashState as BacklashState
from .dead_zone import DeadZone as DeadZone
from .identity import Identity as Identity
from .output_scaled import OutputScaled as OutputScaled
from .piecewise_linear import (
    PiecewiseLinear as PiecewiseLinear,
    piecewise_linear_map as piecewise_linear_map,
)
from .saturation import Saturation as Saturation
from .scaled import Scaled as Scaled
from .shifted import Shifted as Shifted
from .tabulated import Tabulated as Tabulated
