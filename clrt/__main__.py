import sys

from clrt.cli import main

sys.exit(main())
