"""``python -m cdpr_twin`` runs the ``cdpr-twin`` command."""

import sys

from cdpr_twin.cli import main

sys.exit(main())
