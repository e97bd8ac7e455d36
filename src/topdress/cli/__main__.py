"""`python -m topdress.cli`: the `topdress` command."""

import sys

from topdress.cli.main import main

sys.exit(main())
