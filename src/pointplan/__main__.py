"""``python -m pointplan``."""

from .cli import main

raise SystemExit(main())
