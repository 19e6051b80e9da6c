"""``glsynth`` and ``python -m glsynth``: the command line (glsynth.cli), imported with Ctrl-C
held (glsynth.core.interrupts says why), so a Ctrl-C while it loads stops the command."""

import sys

from glsynth.core.interrupts import held_interrupt


def main() -> int:
    try:
        with held_interrupt():
            from glsynth import cli
    except KeyboardInterrupt:
        print("glsynth: interrupted while starting", file=sys.stderr)
        return 130
    return cli.main()


if __name__ == "__main__":
    sys.exit(main())
