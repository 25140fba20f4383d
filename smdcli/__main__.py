"""Allow ``python -m smdcli``.

The top, beside cli.py: may import anything.
"""

from smdcli.cli import main

main()
