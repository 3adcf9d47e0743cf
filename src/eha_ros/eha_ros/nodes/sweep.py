"""sweep node (not built yet: issue 8)."""
import sys

from .common import not_implemented


def main() -> int:
    return not_implemented('sweep', 8)


if __name__ == '__main__':
    sys.exit(main())
