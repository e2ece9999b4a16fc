"""``python -m handcap.cli``."""

import sys

from handcap.cli.main import main

sys.exit(main())
