"""Registered studies of the gap diagnosis (`hamjax study --list`)."""
