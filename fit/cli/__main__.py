"""``python -m fit.cli``: the ``rbrdf-fit`` command line (:func:`fit.cli.main`)."""
import sys

from . import main

if __name__ == "__main__":
    sys.exit(main())
