"""The error a user can fix: the CLI prints it in one line and exits with status 2."""


class UserInputError(ValueError):
    """Bad input from a user (file, option or data); the message names the problem."""
