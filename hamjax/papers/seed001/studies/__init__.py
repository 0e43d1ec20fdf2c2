"""Registered studies of seed 001: one module per claim (`hamjax study --list`)."""
