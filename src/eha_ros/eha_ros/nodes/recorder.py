"""recorder node (not built yet: issue 10)."""
import sys

from .common import not_implemented


def main() -> int:
    return not_implemented('recorder', 10)


if __name__ == '__main__':
    sys.exit(main())
