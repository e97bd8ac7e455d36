"""`python -m topdress.display --fd N`: the display process the terminal starts."""

import sys

from topdress.display.process import main

sys.exit(main())
