import sys

from warpsky.cli import main

sys.exit(main())
