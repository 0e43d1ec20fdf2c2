"""Registered Monte Carlo studies: one module per study, found by `discover_studies`."""
