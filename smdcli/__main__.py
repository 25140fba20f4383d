"""`smd` and `python -m smdcli`: interrupts first, then the command line.

The signal handlers go in before anything heavy is imported (typer, rich: a tenth of a second and more), so a
Ctrl-C or SIGTERM that lands while the command line is being imported ends the run as one anywhere else does
(exit 130 or 143, one line), not as a traceback. The top, beside cli.py: may import anything.
"""

import signal
import sys

try:
    from smdcli import interrupts
except KeyboardInterrupt:  # a Ctrl-C in the instant before there is a handler to take it: still one line
    import os

    print("smd: interrupted while starting; nothing was written", file=sys.stderr)
    sys.stderr.flush()
    os._exit(130)


def main() -> None:
    """Console-script entry point."""
    try:
        interrupts.install()
        from smdcli.cli import main as command_line

        command_line()  # from its first lines on, it reports an interrupt itself; this covers the import before
    except KeyboardInterrupt:
        import os

        signum = interrupts.settle()
        print(f"smd: {'terminated' if signum == signal.SIGTERM else 'interrupted'} while starting; nothing was written",
              file=sys.stderr)
        sys.stderr.flush()
        os._exit(interrupts.exit_code(signum or 2))


if __name__ == "__main__":
    main()
