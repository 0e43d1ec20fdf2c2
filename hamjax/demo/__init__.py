"""The built-in demonstration (`hamjax demo`): one section per module, each
defining `run(key, out) -> [(file, description), ...]`."""
