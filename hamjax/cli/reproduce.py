"""`hamjax reproduce NAME --out DIR`: reproduce a paper's simulation example."""

from ._methods import register_method_commands


def register(sub) -> None:
    register_method_commands(sub, "reproduce", "reproduce a paper's example")
