"""Named jaxtyping aliases shared across hamjax (the diffrax `_custom_types.py` idea)."""

from typing import TypeAlias

import numpy as np
from jaxtyping import Array, ArrayLike, Float, Int, PRNGKeyArray


Signal: TypeAlias = Float[Array, " time"]
SignalLike: TypeAlias = Float[ArrayLike, " time"]
Times: TypeAlias = Float[Array, " time"]
Params: TypeAlias = Float[Array, " n_params"]
Scalar: TypeAlias = Float[Array, ""]
ScalarLike: TypeAlias = float | int | Float[ArrayLike, ""]
IntScalarLike: TypeAlias = int | Int[ArrayLike, ""]
Key: TypeAlias = PRNGKeyArray
NumpyArray: TypeAlias = np.ndarray
