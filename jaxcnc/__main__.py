import sys

from jaxcnc.cli.main import main

sys.exit(main())
