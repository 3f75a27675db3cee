"""``python -m hollowtree``: the command line."""

from hollowtree.pipeline.cli import main

if __name__ == "__main__":
    raise SystemExit(main())
