"""The `livezmp` command. Each subcommand lives in the module of its idea; user
mistakes (:class:`InputError`) print one line and exit with code 2."""

from __future__ import annotations

import argparse
import sys

from livezmp.commands.analyze import add_analyze_command
from livezmp.commands.correct import add_correct_command
from livezmp.commands.monitor import add_monitor_commands
from livezmp.commands.run import add_run_commands
from livezmp.errors import InputError
from livezmp.gait.cli import add_gait_commands


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="livezmp", description="Real-time balance monitor for humanoid motion.")
    sub = p.add_subparsers(dest="command", required=True)
    add_analyze_command(sub)
    add_correct_command(sub)
    add_monitor_commands(sub)
    add_run_commands(sub)
    add_gait_commands(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except InputError as e:
        print(f"livezmp: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
