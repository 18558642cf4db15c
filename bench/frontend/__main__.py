"""`python -m bench.frontend` is `bench frontend`: the front end alone (`bench.cli.frontend`)."""

import sys

from bench.cli import main

sys.exit(main(["frontend", *sys.argv[1:]]))
