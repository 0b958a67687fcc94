"""The ``orokit`` process leaves without the interpreter's teardown (numba's costs ~0.3 CPU s), yet
with the exit status, flushed output and exit handlers of a normal exit."""
from __future__ import annotations

import subprocess
import sys

#: a process running the CLI as the console script does (``cli()`` without arguments); an object
#: whose finalizer prints shows whether the interpreter was torn down
SCRIPT = """
import atexit, sys, threading, time
from orokit.cli.main import cli
class Probe:
    def __del__(self):
        print("torn down", flush=True)
probe = Probe()
atexit.register(lambda: print("exit handlers ran"))
if sys.argv[1] == "thread":  # a non-daemon thread still running at the end: the normal exit waits for it
    threading.Thread(target=time.sleep, args=(0.5,)).start()
sys.argv = ["orokit", *sys.argv[2:]]
cli()
"""


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", SCRIPT, *args], capture_output=True, text=True, timeout=120)


def test_console_exit_skips_the_teardown_but_not_the_exit_handlers():
    res = _run("plain", "--version")
    assert res.returncode == 0
    # stdout is a pipe (block-buffered): the version line is there only because it was flushed
    assert res.stdout.splitlines() == ["orokit, version " + _version(), "exit handlers ran"]


def test_console_exit_keeps_the_status_and_stderr_of_an_error():
    res = _run("plain", "no-such-command")
    assert res.returncode == 2
    assert "No such command 'no-such-command'" in res.stderr
    assert res.stdout.splitlines() == ["exit handlers ran"]


def test_console_exit_waits_for_a_running_thread():
    res = _run("thread", "--version")
    assert res.returncode == 0
    assert res.stdout.splitlines() == ["orokit, version " + _version(), "exit handlers ran", "torn down"]


def test_in_process_call_with_arguments_returns():
    """``cli([...], standalone_mode=False)`` (scripts, tests) is click's plain call: no exit at all."""
    code = ("from orokit.cli.main import cli\n"
            "cli(['--help'], standalone_mode=False)\n"
            "print('still here')\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert res.stdout.splitlines()[-1] == "still here"


def _version() -> str:
    from orokit import __version__

    return __version__
