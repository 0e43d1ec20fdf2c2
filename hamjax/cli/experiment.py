"""`hamjax experiment METHOD ...`: design an excitation, write experiment.json + input.csv."""

from ._methods import register_method_commands


def register(sub) -> None:
    register_method_commands(sub, "experiment", "design an experiment (input.csv)")
