"""``python -m nnid``: the ``nnid`` command, for an environment whose scripts are not on PATH."""

from nnid.cli import main

main()
