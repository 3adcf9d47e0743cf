"""switch_manager node (not built yet: issue 7)."""
import sys

from .common import not_implemented


def main() -> int:
    return not_implemented('switch_manager', 7)


if __name__ == '__main__':
    sys.exit(main())
