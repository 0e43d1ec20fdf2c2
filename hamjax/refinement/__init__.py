from ._parametrisation import AbstractParametrisation as AbstractParametrisation
from .backlash_path import (
    BacklashPathParametrisation as BacklashPathParametrisation,
    cycle_positions as cycle_positions,
)
from .closed_form import (
    refine_fgi_result as refine_fgi_result,
    refine_nbbi_result as refine_nbbi_result,
    refine_recursive_pl_result as refine_recursive_pl_result,
)
from .crlb import (
    cramer_rao_bound as cramer_rao_bound,
    fisher_information as fisher_information,
    output_jacobian as output_jacobian,
    standard_errors as standard_errors,
)
from .fgi_frequency import (
    FGIBlock as FGIBlock,
    FGIFrequencyParametrisation as FGIFrequencyParametrisation,
)
from .impulse_table import ImpulseTableParametrisation as ImpulseTableParametrisation
from .options import RefinementOptions as RefinementOptions
from .piecewise_linear import (
    PiecewiseLinearParametrisation as PiecewiseLinearParametrisation,
)
from .prediction_error import RefinementResult as RefinementResult, refine as refine
from .steiglitz_mcbride import steiglitz_mcbride_table as steiglitz_mcbride_table
