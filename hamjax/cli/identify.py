"""`hamjax identify METHOD DIR`: read data.csv, write result.json."""

from ._methods import register_method_commands


def register(sub) -> None:
    register_method_commands(
        sub, "identify", "identify from a measured experiment folder"
    )
