import sys

from trackcli.sample_data import _main

sys.exit(_main())
