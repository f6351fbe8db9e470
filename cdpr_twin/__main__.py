"""``python -m cdpr_twin`` runs the ``cdpr-twin`` command (:mod:`cdpr_twin.entry`)."""

import sys

from cdpr_twin.entry import main

sys.exit(main())
