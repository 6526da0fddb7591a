"""The one exception type for known failures.

Library code raises :class:`DcslamError` for bad input, a missing file or an artefact that would be overwritten;
the command line prints its message as one line on stderr and exits with code 1. Any other exception is a bug.
"""


class DcslamError(Exception):
    """A known failure, told to the user as one line: what was wrong, which file, what to do."""
