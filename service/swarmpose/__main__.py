"""``python -m swarmpose ...`` is the ``swarmpose`` command."""

import sys

from swarmpose.cli.main import main

sys.exit(main())
