"""hardware_bridge node (not built yet: issue 9)."""
import sys

from .common import not_implemented


def main() -> int:
    return not_implemented('hardware_bridge', 9)


if __name__ == '__main__':
    sys.exit(main())
