"""``python -m pmpm``: the same command line as the ``pmpm`` console script."""
import sys

from pmpm.cli import main

if __name__ == "__main__":
    sys.exit(main())
