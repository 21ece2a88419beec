"""`python -m so101.cli`: the `so101` command without its installed script."""

import sys

from so101.cli.main import main

sys.exit(main())
