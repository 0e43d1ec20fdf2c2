from .seed000.fgi_table2 import FGIResult as FGIResult, identify_fgi as identify_fgi
from .seed000.nbbi_table1 import (
    NBBIResult as NBBIResult,
    identify_nbbi as identify_nbbi,
)
from .seed001 import (
    RecursivePLEstimate as RecursivePLEstimate,
    RecursivePLResult as RecursivePLResult,
    identify_recursive_pl as identify_recursive_pl,
)
