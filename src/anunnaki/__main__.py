"""``python -m anunnaki`` runs the command line."""

import sys

from anunnaki.cli.main import main

sys.exit(main())
