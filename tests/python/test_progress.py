"""Progress lines (run/progress.hpp) of long work: drawn on a terminal (a pseudo-terminal by `script`),
never into a pipe or a file, never with -q. A line is drawn once a quarter second has passed, so each
terminal run is sized from a piped run to last about a second or more; where the machine's load fell
between the two (the terminal run then ends sooner than a quarter second), the work is doubled and
run again, up to a bound."""
import math
import shutil
import subprocess
import time

import pytest


def on_terminal(command):
    """stdout + stderr of `command` run on a pseudo-terminal (util-linux script)."""
    if not shutil.which("script"):
        pytest.skip("no `script` to make a terminal")
    p = subprocess.run(["script", "-qec", " ".join(map(str, command)), "/dev/null"], capture_output=True, text=True)
    assert p.returncode == 0, p.stdout + p.stderr
    return p.stdout


def shown_when_long_enough(command, size, most, marker):
    """The terminal output of command(size), the size doubled (up to `most`) while `marker` is absent."""
    while True:
        shown = on_terminal(command(size))
        if marker in shown or size >= most:
            return shown, size
        size = min(most, 2 * size)


def timed(cli, *args):
    t0 = time.perf_counter()
    run = cli(*args)
    return run, time.perf_counter() - t0


def test_generate_draws_on_a_terminal_only(tmp_path, cli):
    binary = cli("--version").args[0]
    piped, seconds = timed(cli, "generate", tmp_path / "a.h5", "-n", 1 << 20)
    assert piped.stderr == "" and "\x1b" not in piped.stdout
    n = min(1 << 25, (1 << 20) * max(2, math.ceil(1.5 / seconds)))
    shown, n = shown_when_long_enough(lambda k: [binary, "generate", tmp_path / "b.h5", "-n", k], n, 1 << 25,
                                      "generate:")
    assert "generate:" in shown and "bodies" in shown and "\x1b[K" in shown
    assert "generate:" not in on_terminal([binary, "generate", tmp_path / "c.h5", "-n", n, "-q"])


def test_detect_steps_draw_on_a_terminal_only(tmp_path, cli):
    binary = cli("--version").args[0]
    cli("generate", tmp_path / "s.h5", "-n", 1 << 16, "-q")
    command = ["detect", tmp_path / "s.h5", "-o", tmp_path / "c.h5", "--backend", "cpu", "--steps"]
    piped, seconds = timed(cli, *command, 10)
    assert "detect: resident steps: " not in piped.stderr + piped.stdout and "\x1b" not in piped.stderr
    steps = min(2000, max(20, math.ceil(10 * 1.5 / seconds)))
    shown, _ = shown_when_long_enough(lambda k: [binary, *command, k], steps, 2000, "detect: resident steps: ")
    assert "detect: resident steps: " in shown
