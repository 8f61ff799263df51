import sys

from bevflow_services.cli import main

sys.exit(main())
