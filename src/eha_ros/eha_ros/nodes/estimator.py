"""estimator node (not built yet: issue 4)."""
import sys

from .common import not_implemented


def main() -> int:
    return not_implemented('estimator', 4)


if __name__ == '__main__':
    sys.exit(main())
