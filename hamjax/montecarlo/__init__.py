"""Monte Carlo engine: chunked, sharded, resumable runs; summaries; study registry."""

from .config import MonteCarloConfig as MonteCarloConfig
from .registry import (
    Study as Study,
    StudyOption as StudyOption,
    discover_studies as discover_studies,
    get_study as get_study,
    option_values as option_values,
    register_study as register_study,
)
from .runner import run_monte_carlo as run_monte_carlo
from .statistics import (
    LogLogSlope as LogLogSlope,
    MonteCarloSummary as MonteCarloSummary,
    loglog_slope as loglog_slope,
    summarise as summarise,
)
