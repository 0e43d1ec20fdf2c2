from .fgi import FGIResult as FGIResult, identify_fgi as identify_fgi
from .nbbi import NBBIResult as NBBIResult, identify_nbbi as identify_nbbi
from .recursive_pl import (
    RecursivePLEstimate as RecursivePLEstimate,
    RecursivePLResult as RecursivePLResult,
    identify_recursive_pl as identify_recursive_pl,
)
