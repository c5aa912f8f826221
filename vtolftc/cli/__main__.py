"""``python -m vtolftc.cli``: the same as the ``vtolftc`` command."""

import sys

from vtolftc.cli.main import main

sys.exit(main())
