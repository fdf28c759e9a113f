"""``python -m mbcomp``: the command line (``mbcomp --help``)."""
from mbcomp.face.cli import main

raise SystemExit(main())
