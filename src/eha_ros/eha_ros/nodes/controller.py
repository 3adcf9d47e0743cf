"""controller node (not built yet: issue 6)."""
import sys

from .common import not_implemented


def main() -> int:
    return not_implemented('controller', 6)


if __name__ == '__main__':
    sys.exit(main())
