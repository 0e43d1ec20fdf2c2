from ._base import (
    AbstractContinuousLinearBlock as AbstractContinuousLinearBlock,
    AbstractDiscreteLinearBlock as AbstractDiscreteLinearBlock,
    AbstractLinearBlock as AbstractLinearBlock,
)
from .continuous_tf import ContinuousTransferFunction as ContinuousTransferFunction
from .discrete_tf import DiscreteTransferFunction as DiscreteTransferFunction
from .state_space import DiscreteStateSpace as DiscreteStateSpace
