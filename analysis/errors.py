"""The one exception type the user sees: a one-line message, no traceback."""


class UserError(Exception):
    """A problem with the user's input, said in one line that names it and what to do.

    The CLI prints ``analyze: error: <message>`` and exits with ``exit_code``.
    """

    exit_code = 2

    def __init__(self, message: str, exit_code: int | None = None):
        super().__init__(message)
        if exit_code is not None:
            self.exit_code = exit_code
