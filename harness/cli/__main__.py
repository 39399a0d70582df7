"""``python -m harness.cli``: the same as the ``sslpv-harness`` console command."""

import sys

from harness.cli.main import main

sys.exit(main())
