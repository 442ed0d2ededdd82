"""``python -m uavris COMMAND [FLAGS]``: the same as the ``uavris`` command (:mod:`uavris.cli`)."""

import sys

from uavris.cli import main

sys.exit(main())
