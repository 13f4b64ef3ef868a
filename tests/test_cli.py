"""The command line as a user meets it: help on every command and option, the top-level help
naming exactly the commands that exist, progress bars only on a terminal, ``-q`` everywhere."""
import contextlib
import fcntl
import io
import os
import pty
import re
import struct
import subprocess
import sys
import termios

import pytest

from tests.conftest import run_cli

SPEC = """name: clitiny
seed: 3
sequences: 1
pad_ppm: 400
camera: {width: 64, height: 64, fps: 2}
trajectory: {start_height_m: 3.0, duration_s: [3.0, 3.0], lateral_offset_m: [0.0, 0.3], families: [straight]}
"""


def _help(argv) -> str:
    from hvloc.cli import main

    out = io.StringIO()
    with contextlib.redirect_stdout(out), pytest.raises(SystemExit) as ex:
        main([*argv, "--help"])
    assert ex.value.code == 0, argv
    return out.getvalue()


def _subcommands(text: str) -> list:
    m = re.search(r"\{([a-z0-9_,-]+)\}", text)
    return m.group(1).split(",") if m else []


def test_every_command_and_option_has_help_and_the_top_level_lists_what_exists():
    from hvloc.cli import COMMANDS, USAGE

    listed = re.findall(r"^  (\S+)\s", USAGE, flags=re.M)
    assert listed == list(COMMANDS)
    seen = 0
    for cmd in COMMANDS:
        text = _help([cmd])  # building a parser raises on an argument without help
        for sub in _subcommands(text):
            sub_text = _help([cmd, sub])
            assert "usage:" in sub_text, (cmd, sub)
            seen += 1
    assert seen >= 9
    # what the top-level help promises under "bench" are real subcommands
    bench = _subcommands(_help(["bench"]))
    for word in ("run", "sweep", "compare", "leaderboard", "diagnose"):
        assert word in COMMANDS["bench"][1] and word in bench


def test_an_option_without_help_is_refused_when_the_parser_is_built():
    from pad_design.errors import ArgumentParser

    p = ArgumentParser(prog="x")
    with pytest.raises(ValueError, match="--thing has no help"):
        p.add_argument("--thing")


@pytest.fixture(scope="module")
def spec_file(tmp_path_factory):
    p = tmp_path_factory.mktemp("cli") / "clitiny.yaml"
    p.write_text(SPEC)
    return p


def test_progress_bars_only_on_a_terminal(spec_file, tmp_path):
    env = {**os.environ, "PYOPENGL_PLATFORM": "osmesa"}
    # stderr is a pipe (a log file, CI): nothing on it
    r = run_cli("generate", spec_file, "--out", tmp_path / "ds", env=env)
    assert r.returncode == 0 and r.stderr == "", r.stderr
    r = run_cli("localize", tmp_path / "ds", "--out", tmp_path / "est", env=env)
    assert r.returncode == 0 and r.stderr == "", r.stderr
    assert (tmp_path / "est" / "seq_0000" / "estimates.csv").is_file()
    # stderr is a terminal: the bar is drawn, and -q silences it
    for quiet, want_bar in (([], True), (["-q"], False)):
        master, slave = pty.openpty()
        fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))  # a terminal 100 wide
        p = subprocess.Popen([sys.executable, "-m", "hvloc.cli", "localize", str(tmp_path / "ds"), "--out",
                              str(tmp_path / f"est{len(quiet)}"), *quiet], stderr=slave, stdout=subprocess.DEVNULL,
                             env=env)
        os.close(slave)
        chunks = []
        while True:
            try:
                data = os.read(master, 4096)
            except OSError:  # the child closed the terminal
                break
            if not data:
                break
            chunks.append(data)
        os.close(master)
        assert p.wait() == 0
        err = b"".join(chunks).decode(errors="replace")
        assert ("localize" in err and "frame" in err) == want_bar, (quiet, err)


def test_quiet_is_accepted_by_every_command_that_shows_progress():
    for argv in (["generate"], ["localize"], ["bench", "run"], ["bench", "sweep"], ["demo"]):
        text = _help(argv)
        assert "-q, --quiet" in text, argv
