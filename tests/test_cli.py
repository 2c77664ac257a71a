"""The command line's grammar: light to parse, in step with what the commands run."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from livezmp.cli import BSP_NAMES, DEFAULT_DASHBOARD, SCENARIO_NAMES, SIM_LINKS, build_parser
from livezmp.live.scenarios import SCENARIOS
from livezmp.model.anthropometry import BSP_CHOICES
from livezmp.monitor.dashboard import parse_address
from sim_devices.launch import KINDS

HEAVY = ("scipy", "pinocchio", "matplotlib", "mcap", "websockets", "serial", "can", "dynamixel_sdk", "sim_devices")


def test_grammar_names_match_the_commands():
    assert SCENARIO_NAMES == tuple(SCENARIOS)
    assert SIM_LINKS == tuple(KINDS)
    assert BSP_NAMES == BSP_CHOICES
    assert parse_address(DEFAULT_DASHBOARD) == ("127.0.0.1", 8765)


def test_every_subcommand_names_a_handler_that_exists():
    import importlib

    parser = build_parser()
    actions = [a for a in parser._actions if a.dest == "command"][0].choices
    seen = 0
    for name, sub in actions.items():
        subs = [a for a in sub._actions if getattr(a, "choices", None) and a.dest in ("gait_command", "batch_command")]
        for p in (subs[0].choices.values() if subs else [sub]):
            module, _, function = p.get_default("handler").partition(":")
            assert callable(getattr(importlib.import_module(module), function)), (name, module, function)
            seen += 1
    assert seen == 15  # analyze calibrate correct monitor replay recover run sim demo, gait analyze/synth/compare,
    # batch analyze/correct/gait


def test_help_and_every_subcommand_help_import_nothing_heavy():
    code = ("import sys, contextlib, io\nfrom livezmp.cli import build_parser\n"
            "for argv in ([], ['analyze'], ['correct'], ['monitor'], ['run'], ['sim'], ['demo'], ['gait', 'synth'],"
            " ['batch', 'analyze']):\n"
            "    with contextlib.suppress(SystemExit), contextlib.redirect_stdout(io.StringIO()):\n"
            "        build_parser().parse_args([*argv, '--help'])\n"
            "import json; print(json.dumps(sorted(m for m in sys.modules if '.' not in m)))")
    loaded = set(json.loads(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                           check=True).stdout))
    assert not loaded & set(HEAVY), loaded & set(HEAVY)


def test_version():
    out = subprocess.run([sys.executable, "-m", "livezmp", "--version"], capture_output=True, text=True, check=True)
    assert out.stdout.startswith("livezmp ") and out.stdout.split()[1][0].isdigit()


def test_a_reader_that_goes_away_ends_the_command_quietly():
    """`livezmp analyze | head -1` style: the pipe closed before the lines are written gives no traceback and no
    "Exception ignored" at exit, only SIGPIPE's exit status."""
    proc = subprocess.Popen([sys.executable, "-m", "livezmp", "analyze"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    proc.stdout.close()  # the reader is gone before the built-in demo's summary lines are printed
    err = proc.stderr.read()
    assert proc.wait(timeout=120) == 141
    assert err == "", err


@pytest.mark.parametrize("argv", [["frobnicate"], [], ["analyze", "--cutoff-hz", "abc"], ["analyze", "--bogus"],
                                  ["demo", "--link", "nosuch"]])
def test_a_mistyped_command_line_is_one_line_and_exit_2(argv, capsys):
    """argparse's own errors (usage, then the error) are one line, as every other user mistake's."""
    from livezmp.cli import main

    with pytest.raises(SystemExit) as e:
        main(argv)
    err = capsys.readouterr().err
    assert e.value.code == 2 and err.count("\n") == 1 and "error:" in err and "--help" in err, err
