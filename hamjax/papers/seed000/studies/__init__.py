"""Registered studies of seed 000: one module per claim (`hamjax study --list`)."""
