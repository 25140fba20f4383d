"""Allow ``python -m smdcli``."""

from smdcli.cli import main

main()
