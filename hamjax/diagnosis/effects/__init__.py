from ._base import AbstractEffect as AbstractEffect, StartContext as StartContext
from .backlash import BacklashEffect as BacklashEffect
from .coloured_noise import ColouredNoiseEffect as ColouredNoiseEffect
from .dead_zone import DeadZoneEffect as DeadZoneEffect
from .drift import DriftEffect as DriftEffect
from .extra_pole import ExtraPoleEffect as ExtraPoleEffect
from .feedback_nonlinearity import (
    FeedbackNonlinearityEffect as FeedbackNonlinearityEffect,
)
from .friction import FrictionEffect as FrictionEffect
from .output_nonlinearity import OutputNonlinearityEffect as OutputNonlinearityEffect
from .parameter_mismatch import ParameterMismatch as ParameterMismatch
from .preload import PreloadEffect as PreloadEffect
from .rate_limit import RateLimitEffect as RateLimitEffect
from .saturation import SaturationEffect as SaturationEffect
from .time_delay import TimeDelayEffect as TimeDelayEffect
