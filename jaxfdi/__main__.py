import sys

from jaxfdi.cli import main

sys.exit(main())
