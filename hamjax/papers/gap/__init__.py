"""Withheld-effect cases for the sim-to-real gap diagnosis: the blind-case
generator and scorer (`blind.py`, behind `hamjax blind`), the demo case, and the
studies (`studies/`: the blind benchmark and the real-data table)."""
