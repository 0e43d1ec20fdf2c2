"""Registered studies of the engine (`hamjax study --list`)."""
