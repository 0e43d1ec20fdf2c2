from .designs import FGIDesign as FGIDesign
from .impulse_pe import pe_impulse_sequence as pe_impulse_sequence
from .random import (
    multisine as multisine,
    prbs as prbs,
    random_staircase as random_staircase,
)
from .staircase import (
    fgi_period_samples as fgi_period_samples,
    initialisation_step as initialisation_step,
    nbbi_staircase as nbbi_staircase,
    periodic_staircase as periodic_staircase,
    staircase_cycle_levels as staircase_cycle_levels,
)
