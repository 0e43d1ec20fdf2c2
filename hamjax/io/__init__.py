from .csv import (
    count_rows as count_rows,
    read_csv as read_csv,
    sampling_period as sampling_period,
    write_csv as write_csv,
)
from .experiment_folder import read_data as read_data, read_design as read_design
from .files import (
    atomic_write_text as atomic_write_text,
    read_json as read_json,
    write_json as write_json,
)
from .gap_case import write_case as write_case
from .model_json import (
    linear_from_dict as linear_from_dict,
    load_model as load_model,
    model_to_dict as model_to_dict,
    nonlinearity_from_dict as nonlinearity_from_dict,
    require_stable as require_stable,
)
