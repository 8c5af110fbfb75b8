import sys

from jassy.apps.cli import main

sys.exit(main())
