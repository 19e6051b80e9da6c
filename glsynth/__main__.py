"""``glsynth`` and ``python -m glsynth``: the command line (glsynth.cli), imported with Ctrl-C
held (glsynth.core.interrupts says why), so a Ctrl-C while it loads stops the command; so are
the packages that would swallow one, whenever a command imports them."""

import sys

from glsynth.core.interrupts import held_interrupt, hold_while_importing


def main() -> int:
    """Run the command line; exit code 130 for a Ctrl-C before its command has begun (a
    command that can be resumed says so itself)."""
    hold_while_importing()
    try:
        with held_interrupt():
            from glsynth import cli
        return cli.main()
    except KeyboardInterrupt:
        print("glsynth: interrupted while starting", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
