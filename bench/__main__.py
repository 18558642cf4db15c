"""`python -m bench` is the `bench` command line."""

import sys

from bench.harness.cli import main

sys.exit(main())
