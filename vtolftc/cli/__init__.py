"""Layer 5, the ``vtolftc`` command line: :mod:`.main` parses and dispatches to the
``cmd_*`` modules, one per subcommand."""

from vtolftc.cli.main import main, run

__all__ = ["main", "run"]
