import sys

from jassy.cli import main

sys.exit(main())
