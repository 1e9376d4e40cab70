import sys

from warpsky.cli.main import main

sys.exit(main())
