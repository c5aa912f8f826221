"""The command line's error type, at the bottom of the layers so that every command module can
import it downward (the CLI loads the command modules by name)."""


class UsageError(Exception):
    """Bad input from the user: printed as one line, exit status 2."""
