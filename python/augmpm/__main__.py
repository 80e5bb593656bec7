import sys

from augmpm.cli import main

sys.exit(main())
