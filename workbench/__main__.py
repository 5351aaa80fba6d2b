"""`python -m workbench`: the `workbench` command line."""

import sys

from workbench.cli.main import main

sys.exit(main())
