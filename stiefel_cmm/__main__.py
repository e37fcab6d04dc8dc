"""``python -m stiefel_cmm …`` is the ``stiefel`` command."""

import sys

from stiefel_cmm.cli.main import main

sys.exit(main())
