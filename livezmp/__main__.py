import sys

from livezmp.cli import main

sys.exit(main())
