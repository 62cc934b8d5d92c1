"""User-facing errors of the suite."""


class SuiteError(Exception):
    """An error caused by the user's input or environment, printed as one line by the CLI."""
