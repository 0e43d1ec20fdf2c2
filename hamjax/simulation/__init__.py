from .batch import simulate_batch as simulate_batch
from .continuous import simulate_diffrax as simulate_diffrax
from .discrete import (
    check_stable as check_stable,
    linear_response as linear_response,
    simulate as simulate,
)
