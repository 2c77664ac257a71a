"""The one exception type for user mistakes: bad files, bad options, bad packets.

The CLI prints its message as a single line and exits with code 2; library callers
catch it like any other exception. Messages name the file, line, joint or field.
"""


class InputError(ValueError):
    """A user-facing input error; ``str(err)`` is one line naming where the problem is."""
